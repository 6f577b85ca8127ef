"""What a user reads in the errors a bad setting or a refusal raises (rwt_protocol.errors)."""

from __future__ import annotations

import pytest

from rwt_protocol.errors import ConfigError, OpRefusedError, RwtError
from rwt_protocol.levels import StatusLevel


def test_a_refusal_names_the_op_its_id_and_the_servers_reason_once() -> None:
    error = OpRefusedError("advertise", "adv:/t:1", "advertise: /t is established with type X")
    assert str(error) == "the server refused advertise 'adv:/t:1': /t is established with type X"
    assert (error.op, error.op_id) == ("advertise", "adv:/t:1")
    assert error.reason == "advertise: /t is established with type X"  # the status text, whole
    assert isinstance(error, RwtError)


def test_status_levels_parse_their_wire_names_and_refuse_others() -> None:
    assert [StatusLevel.from_wire(t) for t in ("none", "error", "warning", "info")] == list(
        StatusLevel
    )
    assert StatusLevel.from_wire("WARNING") is StatusLevel.WARNING
    with pytest.raises(ConfigError, match="unknown status level 'loud'"):
        StatusLevel.from_wire("loud")
