"""What a server's process tunes: its heap, its collector, its descriptor budget.

Set once when a command starts (``rwt serve``, ``rwt record``, ``rwt play``, the
links); none imports another:

- ``allocator``: keep large message buffers in the heap between messages (glibc,
  ``--heap-keep``; benchmarks B4, B6, B9);
- ``gcfreeze``: keep the start-up objects out of the cyclic collector (B15);
- ``fdlimit``: the soft RLIMIT_NOFILE raised, and the connections it allows
  (``--max-connections``' default).
"""
