"""What an offer SDP must be before the server builds anything for it (docs/webrtc.md, D38).

``check_offer`` reads an offer line by line, as RFC 8866 (SDP), RFC 8839 (ICE's
attributes) and JSEP (RFC 8829) write it, and refuses it with a reason when
aiortc could not use it or when it would make the server work for nothing:

- **well-formed**: ``v=0`` first, then ``<letter>=<value>`` lines (no control
  characters), ``o=``, ``s=`` and ``t=``; every ``m=`` section of a kind aiortc
  answers (``audio``, ``video``, ``application``) with its ``a=mid`` (unique,
  and every ``a=group:BUNDLE`` member one of them), ICE credentials
  (``a=ice-ufrag`` of 4-256 ice-chars, ``a=ice-pwd`` of 22-256), a DTLS
  fingerprint of a hash aiortc checks (SHA-256, -384, -512) with its
  ``a=setup`` (``actpass``, ``active``, ``passive``); audio and video with
  ``a=rtcp-mux`` and payload types aiortc reads; one data channel section at
  most, ``UDP/DTLS/SCTP webrtc-datachannel`` with its ``a=sctp-port``, or the
  older ``DTLS/SCTP <port>``. Each such offer used to be answered (201) and hold
  a connecting slot until the connect deadline, or made aiortc log a
  traceback (a candidate port 99999).
- **bounded**: at most ``MAX_MEDIA_SECTIONS`` media sections (aiortc builds a
  transceiver for each, and without BUNDLE an ICE transport: 600 of them took a
  second of CPU and 80 MB), at most ``MAX_SECTION_CANDIDATES`` candidates a
  section.
- **candidates the server may check**: a remote candidate makes the server send
  STUN connectivity checks to its address. A candidate's address is an IP
  address or an mDNS name (``<uuid>.local``, which aioice resolves on the local
  link; a DNS name would be refused by aioice without a word), its port a real
  one (UDP: 1-65535; a TCP ``active`` candidate's may be 0 or 9), and never a
  loopback, unspecified, multicast, broadcast or reserved address: no browser
  offers one, and checks to them would reach the server's own or every host of
  a network. Over the offer its UDP candidates name at most
  ``MAX_CANDIDATE_ADDRESSES`` distinct addresses (and mDNS names), so one offer
  cannot point the server's checks at hundreds of hosts.

No module here imports aiortc: the rules are the SDP's, and cost one pass over
at most ``MAX_OFFER_BYTES`` of text.
"""

from __future__ import annotations

import ipaddress
import re
from dataclasses import dataclass, field

from rwt_protocol.errors import RemoteProtocolError

__all__ = [
    "MAX_CANDIDATE_ADDRESSES",
    "MAX_MEDIA_SECTIONS",
    "MAX_SECTION_CANDIDATES",
    "OfferError",
    "OfferShape",
    "check_offer",
]

MAX_MEDIA_SECTIONS = 8
"""Media sections (``m=`` lines) of one offer: the data channel, the four video tracks an
offer may ask for (``webrtc.signalling.MAX_VIDEO_TRACKS``) and room for the audio transceivers a
player adds (answered inactive). Past it, 400."""

MAX_SECTION_CANDIDATES = 32
"""ICE candidates (``a=candidate`` lines) of one media section; a browser offers about ten
(host names, TCP host candidates, server-reflexive and relayed ones). Past it, 400."""

MAX_CANDIDATE_ADDRESSES = 16
"""Distinct addresses (and mDNS names) of an offer's UDP candidates, the hosts the server
sends its STUN connectivity checks to. Past it, 400."""

_ICE_CHAR = re.compile(r"[A-Za-z0-9+/]+")
_MDNS = re.compile(r"[A-Za-z0-9-]{1,63}\.local", re.IGNORECASE)  # aioice's mDNS names
_TOKEN = re.compile(r"[!#$%&'*+\-.0-9A-Z^_`a-z{|}~]{1,64}")
_CONTROL = re.compile(r"[\x00-\x08\x0a-\x1f\x7f\x85\u2028\u2029]")
_MEDIA = re.compile(r"m=([^ ]+) ([0-9]{1,5}) ([A-Za-z/]+) (.+)")
_CONNECTION = re.compile(r"IN IP[46] [^ ]+")
_HEX_PAIRS = re.compile(r"[0-9A-Fa-f]{2}(:[0-9A-Fa-f]{2})*")
_DIGEST_BYTES = {"sha-256": 32, "sha-384": 48, "sha-512": 64}  # what aiortc's DTLS checks
_SETUP = ("actpass", "active", "passive")
_RTP_PROFILES = ("UDP/TLS/RTP/SAVPF", "UDP/TLS/RTP/SAVP", "RTP/SAVPF", "RTP/SAVP")
_CANDIDATE_TYPES = ("host", "srflx", "prflx", "relay")
_CHECKED_TYPES = ("host", "srflx", "relay")  # aioice checks these; it drops prflx ones
_FORBIDDEN_PAYLOAD_TYPES = range(72, 77)  # RTCP's packet types (RFC 5761)
_SHOWN = 40  # characters of a bad value an error shows
_NOT_USABLE = "the offer is not a usable SDP offer"


class OfferError(RemoteProtocolError):
    """An offer the server refuses (HTTP 400); the message says what is wrong and where."""


@dataclass(slots=True)
class _Section:
    """One media section as read so far."""

    kind: str
    proto: str
    formats: list[str]
    number: int
    mid: str | None = None
    ufrag: str | None = None
    pwd: str | None = None
    fingerprints: list[str] = field(default_factory=list)
    setup: str | None = None
    rtcp_mux: bool = False
    sctp_port: bool = False
    candidates: int = 0
    payload_types: set[int] = field(default_factory=set)
    formats_used: list[str] = field(default_factory=list)  # a=fmtp's payload types


@dataclass(frozen=True, slots=True)
class OfferShape:
    """What a checked offer holds.

    Attributes:
        kinds: each media section's kind, in order (``audio``, ``video``, ``application``).
        addresses: the distinct addresses and mDNS names of its UDP candidates.
    """

    kinds: tuple[str, ...]
    addresses: frozenset[str]

    @property
    def data_channel(self) -> bool:
        """It offers a data channel (an ``m=application`` section)."""
        return "application" in self.kinds


def _shown(text: str) -> str:
    return repr(text if len(text) <= _SHOWN else text[: _SHOWN - 3] + "...")


def check_offer(sdp: str) -> OfferShape:
    """Check an offer SDP (the rules of the module's docstring).

    Args:
        sdp: the offer's text, at most ``webrtc.signalling.MAX_OFFER_BYTES``.

    Returns:
        Its media kinds and candidate addresses.

    Raises:
        OfferError: the offer breaks a rule; the message names the line and the rule.
    """
    reader = _Reader()
    lines = sdp.split("\n")
    if lines and not lines[-1].strip():
        lines.pop()  # the last line's end
    for number, raw in enumerate(lines, 1):
        line = raw.removesuffix("\r")
        if not line and number > 1:
            continue  # a stray empty line: aiortc skips it too
        try:
            reader.line(line, number)
        except OfferError as exc:
            raise OfferError(f"{_NOT_USABLE}: line {number}: {exc}") from None
    return reader.finish()


class _Reader:
    """Reads an offer's lines in order; ``finish`` checks what only the whole shows."""

    def __init__(self) -> None:
        self.session: set[str] = set()
        self.ufrag: str | None = None
        self.pwd: str | None = None
        self.fingerprints: list[str] = []
        self.setup: str | None = None
        self.bundles: list[list[str]] = []
        self.sections: list[_Section] = []
        self.addresses: set[str] = set()

    def line(self, line: str, number: int) -> None:
        if number == 1:
            if line != "v=0":
                raise OfferError(f"an offer starts with v=0, not {_shown(line)}")
            return
        if _CONTROL.search(line):
            raise OfferError("a control character in the line")
        if len(line) < 2 or line[1] != "=" or not line[0].islower():
            raise OfferError(f"{_shown(line)} is not a <type>=<value> line")
        kind, value = line[0], line[2:]
        if kind == "m":
            self._media(line, number)
        elif kind == "c":
            if not _CONNECTION.fullmatch(value):
                raise OfferError(f"c={_shown(value)} is not IN IP4|IP6 <address>")
        elif kind == "a":
            self._attribute(value)
        elif not self.sections:
            self._session_line(kind, value)

    def _session_line(self, kind: str, value: str) -> None:
        if kind == "o" and len(value.split()) != 6:
            raise OfferError("o= has six fields: user id version IN IP4|IP6 address")
        if kind == "t" and not re.fullmatch(r"[0-9]+ [0-9]+", value):
            raise OfferError(f"t={_shown(value)} is not <start> <stop>")
        self.session.add(kind)

    def _media(self, line: str, number: int) -> None:
        if len(self.sections) >= MAX_MEDIA_SECTIONS:
            raise OfferError(
                f"more than {MAX_MEDIA_SECTIONS} media sections (m= lines): "
                "a data channel and a transceiver a video track need one each"
            )
        if not self.sections:
            missing = {"o", "s", "t"} - self.session
            if missing:
                raise OfferError(f"the session has no {', '.join(sorted(missing))}= line")
        found = _MEDIA.fullmatch(line)
        if found is None or int(found.group(2)) > 65535:
            raise OfferError(f"{_shown(line)} is not m=<kind> <port> <proto> <formats>")
        kind, proto, formats = found.group(1), found.group(3), found.group(4).split()
        section = _Section(kind, proto, formats, len(self.sections) + 1)
        _check_media(section)
        if kind == "application" and any(s.kind == kind for s in self.sections):
            raise OfferError("a second m=application section: one data channel section")
        self.sections.append(section)

    def _attribute(self, value: str) -> None:
        name, _, arg = value.partition(":")
        section = self.sections[-1] if self.sections else None
        if name == "candidate":
            if section is None:
                raise OfferError("a candidate before the first m= line")
            section.candidates += 1
            if section.candidates > MAX_SECTION_CANDIDATES:
                raise OfferError(
                    f"more than {MAX_SECTION_CANDIDATES} candidates in media section "
                    f"{section.number}"
                )
            address = _candidate(arg)
            if address is not None:
                self.addresses.add(address)
                if len(self.addresses) > MAX_CANDIDATE_ADDRESSES:
                    raise OfferError(
                        f"the candidates name more than {MAX_CANDIDATE_ADDRESSES} addresses: "
                        "the server checks no more"
                    )
        elif name in ("ice-ufrag", "ice-pwd", "fingerprint", "setup"):
            self._transport(name, arg, section)
        elif name == "group":
            semantics, *items = arg.split()
            if semantics == "BUNDLE":
                self.bundles.append(items)
        elif section is not None:
            _section_attribute(section, name, arg)

    def _transport(self, name: str, arg: str, section: _Section | None) -> None:
        """ICE credentials and DTLS parameters, of the session or of a section."""
        if name in ("ice-ufrag", "ice-pwd"):
            low = 4 if name == "ice-ufrag" else 22
            if not (low <= len(arg) <= 256 and _ICE_CHAR.fullmatch(arg)):
                raise OfferError(f"a={name} must be {low} to 256 of A-Z a-z 0-9 + /")
        elif name == "fingerprint":
            if len(arg.split()) != 2:
                raise OfferError(f"a=fingerprint:{_shown(arg)} is not <hash> <digest>")
            algorithm, _, digest = arg.partition(" ")
            size = _DIGEST_BYTES.get(algorithm.lower())
            if size is not None and not (
                _HEX_PAIRS.fullmatch(digest) and len(digest) == 3 * size - 1
            ):
                raise OfferError(f"a=fingerprint:{algorithm} {_shown(digest)} is not its digest")
        elif arg not in _SETUP:
            raise OfferError(f"a=setup:{_shown(arg)} is not actpass, active or passive")
        holder: _Section | _Reader = section or self
        if name == "ice-ufrag":
            holder.ufrag = arg
        elif name == "ice-pwd":
            holder.pwd = arg
        elif name == "setup":
            holder.setup = arg
        elif arg.partition(" ")[0].lower() in _DIGEST_BYTES:
            holder.fingerprints.append(arg)

    def finish(self) -> OfferShape:
        """The offer's shape, once its sections are complete."""
        if not self.sections:
            raise OfferError(f"{_NOT_USABLE}: it has no media section (m= line)")
        mids = [s.mid for s in self.sections]
        for section in self.sections:
            self._check_section(section)
        if len(set(mids)) != len(mids):
            raise OfferError(f"{_NOT_USABLE}: two media sections have one a=mid")
        for items in self.bundles:
            unknown = [item for item in items if item not in mids]
            if unknown:
                raise OfferError(
                    f"{_NOT_USABLE}: a=group:BUNDLE names {_shown(unknown[0])}, no section's a=mid"
                )
        return OfferShape(tuple(s.kind for s in self.sections), frozenset(self.addresses))

    def _check_section(self, section: _Section) -> None:
        where = f"{_NOT_USABLE}: media section {section.number}"
        if section.mid is None:
            raise OfferError(f"{where} has no a=mid")
        if not (section.ufrag or self.ufrag) or not (section.pwd or self.pwd):
            raise OfferError(f"{where} has no ICE credentials (a=ice-ufrag, a=ice-pwd)")
        if not (section.fingerprints or self.fingerprints):
            raise OfferError(
                f"{where} has no DTLS fingerprint aiortc checks (a=fingerprint:sha-256 ...)"
            )
        if (section.setup or self.setup) is None:
            raise OfferError(f"{where} has no a=setup")
        if section.kind in ("audio", "video") and not section.rtcp_mux:
            raise OfferError(f"{where} has no a=rtcp-mux: RTP and RTCP share one port")
        for kind in section.formats_used:
            if int(kind) not in section.payload_types:
                raise OfferError(f"{where}: a=fmtp:{kind} names no a=rtpmap payload type")
        legacy = section.proto == "DTLS/SCTP"  # its port is in the m= line
        if section.kind == "application" and not legacy and not section.sctp_port:
            raise OfferError(f"{where} has no a=sctp-port")


def _check_media(section: _Section) -> None:
    """The ``m=`` line's kind, profile and formats."""
    kind, proto, formats = section.kind, section.proto, section.formats
    if kind in ("audio", "video"):
        if proto not in _RTP_PROFILES:
            raise OfferError(f"m={kind} with {_shown(proto)}: WebRTC's is UDP/TLS/RTP/SAVPF")
        for text in formats:
            if not text.isdigit() or int(text) > 127 or int(text) in _FORBIDDEN_PAYLOAD_TYPES:
                raise OfferError(f"m={kind} payload type {_shown(text)} is not 0-71 or 77-127")
    elif kind == "application":
        legacy = proto == "DTLS/SCTP" and len(formats) == 1 and formats[0].isdigit()
        if not legacy and (proto != "UDP/DTLS/SCTP" or formats != ["webrtc-datachannel"]):
            raise OfferError(
                f"m=application {_shown(proto)} {_shown(' '.join(formats))}: a data "
                "channel is UDP/DTLS/SCTP webrtc-datachannel"
            )
        if legacy and not 1 <= int(formats[0]) <= 65535:
            raise OfferError("the SCTP port of m=application is not 1-65535")
    else:
        raise OfferError(f"m={_shown(kind)}: the server answers audio, video and application")


def _section_attribute(section: _Section, name: str, arg: str) -> None:
    """A section's attributes that aiortc reads as numbers or as several fields."""
    if name in ("rtpmap", "fmtp", "rtcp-fb", "ssrc", "extmap", "rtcp"):
        _rtp_attribute(section, name, arg)
    elif name == "mid":
        if not _TOKEN.fullmatch(arg):
            raise OfferError(f"a=mid:{_shown(arg)} is not a token of 1 to 64 characters")
        section.mid = arg
    elif name == "rtcp-mux":
        section.rtcp_mux = True
    elif name == "sctp-port":
        if not arg.isdigit() or not 1 <= int(arg) <= 65535:
            raise OfferError(f"a=sctp-port:{_shown(arg)} is not 1-65535")
        section.sctp_port = True
    elif name == "max-message-size" and not arg.isdigit():
        raise OfferError(f"a=max-message-size:{_shown(arg)} is not a number of bytes")


def _rtp_attribute(section: _Section, name: str, arg: str) -> None:
    """An RTP attribute: payload types, their formats, SSRCs, header extensions."""
    if name == "rtpmap":
        found = re.fullmatch(r"([0-9]{1,3}) [^/ ]+/[0-9]{1,6}(/[0-9]{1,2})?", arg)
        if found is None:
            raise OfferError(f"a=rtpmap:{_shown(arg)} is not <type> <name>/<rate>[/<channels>]")
        section.payload_types.add(int(found.group(1)))
    elif name in ("fmtp", "rtcp-fb"):
        kind, _, rest = arg.partition(" ")
        if not rest or not (kind.isdigit() or (name == "rtcp-fb" and kind == "*")):
            raise OfferError(f"a={name}:{_shown(arg)} is not <payload type> <parameters>")
        if name == "fmtp":
            section.formats_used.append(kind)
    elif name in ("ssrc", "extmap", "rtcp"):
        number = arg.partition(" ")[0].partition("/")[0]
        fields = {"ssrc": r"[0-9]{1,10} [^:]+:.*", "extmap": r"[0-9/a-z]+ \S+", "rtcp": r".+"}
        if not number.isdigit() or not re.fullmatch(fields[name], arg):
            raise OfferError(f"a={name}:{_shown(arg)} is not what RFC 8866 and its kin allow")


def _candidate(text: str) -> str | None:
    """Check one ``a=candidate`` (RFC 8839 5.1): the address the server checks, or None.

    None for a candidate the server does not check (TCP, peer-reflexive).
    """
    fields = text.split()
    if len(fields) < 8 or fields[6] != "typ":
        raise OfferError(
            f"a=candidate:{_shown(text)} is not <foundation> <component> <transport> "
            "<priority> <address> <port> typ <type> ..."
        )
    foundation, component, transport, priority, address, port, _, kind = fields[:8]
    transport = transport.lower()
    if not (len(foundation) <= 32 and _ICE_CHAR.fullmatch(foundation)):
        raise OfferError(f"candidate foundation {_shown(foundation)} is not 1-32 ice-chars")
    if not component.isdigit() or not 1 <= int(component) <= 256:
        raise OfferError(f"candidate component {_shown(component)} is not 1-256")
    if transport not in ("udp", "tcp"):
        raise OfferError(f"candidate transport {_shown(transport)} is not udp or tcp")
    if not priority.isdigit() or not 1 <= int(priority) <= 2**32 - 1:
        raise OfferError(f"candidate priority {_shown(priority)} is not 1 to 2^32-1")
    lowest = 0 if transport == "tcp" else 1  # a TCP active candidate's port is 9 or 0
    if not port.isdigit() or not lowest <= int(port) <= 65535:
        raise OfferError(f"candidate port {_shown(port)} is not {lowest}-65535")
    if kind not in _CANDIDATE_TYPES:
        raise OfferError(f"candidate type {_shown(kind)} is not host, srflx, prflx or relay")
    _extensions(fields[8:])
    host = _address(address)
    return host if transport == "udp" and kind in _CHECKED_TYPES else None


def _extensions(pairs: list[str]) -> None:
    """A candidate's ``raddr``, ``rport`` and ``generation`` (aioice reads the last two)."""
    for name, value in zip(pairs[::2], pairs[1::2], strict=False):
        if name in ("rport", "generation") and not (value.isdigit() and int(value) <= 2**32):
            raise OfferError(f"candidate {name} {_shown(value)} is not a number")
        if name == "raddr" and _MDNS.fullmatch(value) is None:
            try:
                ipaddress.ip_address(value)
            except ValueError:
                raise OfferError(f"candidate raddr {_shown(value)} is not an address") from None


def _address(text: str) -> str:
    """A candidate's address as the server would check it: an IP address or an mDNS name."""
    if _MDNS.fullmatch(text):
        return text.lower()
    try:
        address = ipaddress.ip_address(text)
    except ValueError:
        raise OfferError(
            f"candidate address {_shown(text)} is not an IP address or an mDNS name (.local)"
        ) from None
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        address = address.ipv4_mapped
    if (
        address.is_loopback
        or address.is_unspecified
        or address.is_multicast
        or address.is_reserved
        or address == ipaddress.IPv4Address("255.255.255.255")
    ):
        raise OfferError(
            f"candidate address {_shown(text)} is a loopback, unspecified, multicast or "
            "reserved address: the server sends no checks there"
        )
    return str(address)
