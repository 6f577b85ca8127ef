"""``rwt ARGS`` for the tests: run by this worker's warm ``rwt`` (zygote.py), or cold.

Run as ``python -S warm_rwt.py ARGS`` (the standard library only, no site: a few ms).
With ``RWT_TEST_WARM`` naming a zygote's socket, and ``RWT_TEST_COLD`` unset, the
zygote forks ``rwt ARGS`` in this process's stdio, working directory and environment;
this process stands for it: signals sent here are passed on, and it ends as the run
ended (its exit code, or killed by the same signal). If it is killed outright, the
zygote kills the run. Anything else (no zygote, a ``cold`` answer, an error) execs the
real ``python -m rwt ARGS`` in this process, as if nothing had been here.

``warm_rwt.py --python ARGS`` does the same for a Python command line (``-c CODE ...``
or ``SCRIPT ...``): the tests' Python clients, with roslibpy's libraries preloaded.
"""

import array
import json
import os
import resource
import signal
import socket
import sys

FORWARDED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP, signal.SIGUSR1, signal.SIGUSR2)


#: ``--python ARGS``: a Python command line (``-c CODE ...``, ``SCRIPT ...``), not ``rwt``.
PYTHON = sys.argv[1:2] == ["--python"]
ARGV = sys.argv[2:] if PYTHON else sys.argv[1:]


def cold() -> None:
    command = [] if PYTHON else ["-m", "rwt"]
    os.execv(sys.executable, [sys.executable, *command, *ARGV])


def warm(path: str) -> None:
    conn = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        conn.connect(path)
        request = {
            "argv": ARGV,
            "python": PYTHON,
            "cwd": os.getcwd(),
            "env": dict(os.environ),
            "nofile": list(resource.getrlimit(resource.RLIMIT_NOFILE)),
            # what this process was started ignoring, as a new interpreter would keep it
            "ignored": [int(n) for n in FORWARDED if signal.getsignal(n) == signal.SIG_IGN],
        }
        fds = array.array("i", [0, 1, 2])
        conn.sendmsg(
            [json.dumps(request).encode() + b"\n"], [(socket.SOL_SOCKET, socket.SCM_RIGHTS, fds)]
        )
        reader = conn.makefile("rb")
        first = reader.readline().decode()
    except OSError:
        conn.close()
        return
    if not first.startswith("pid "):
        conn.close()
        return
    pid = int(first.split()[1])
    for number in FORWARDED:
        signal.signal(number, lambda n, _f: os.kill(pid, n))
    # The run holds the caller's stdio now: let go of ours, so that its end is their EOF.
    null = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1, 2):
        os.dup2(null, fd)
    while True:
        try:
            line = reader.readline().decode()
            break
        except InterruptedError:
            continue
    if not line.startswith("exit "):
        os._exit(1)
    status = int(line.split()[1])
    if os.WIFSIGNALED(status):
        number = os.WTERMSIG(status)
        signal.signal(number, signal.SIG_DFL)
        os.kill(os.getpid(), number)
    os._exit(os.waitstatus_to_exitcode(status) if os.WIFEXITED(status) else 1)


if __name__ == "__main__":
    zygote = os.environ.get("RWT_TEST_WARM")
    if zygote and not os.environ.get("RWT_TEST_COLD"):
        warm(zygote)
    cold()
