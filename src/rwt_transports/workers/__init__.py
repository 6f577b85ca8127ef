"""The processes of ``rwt serve --workers N``: supervised, counted, placing connections.

N server processes share one port (``SO_REUSEPORT``) and one graph over the links
(docs/scaling.md). Modules, each importing only those after it:

- ``supervisor``: the parent: starts the workers, restarts one that dies, stops
  them (``run_workers``, ``WorkerPlan``);
- ``placement``: ``--placement topic``: a connection moves to the worker that owns
  its first topic (D57), by its descriptor and the bytes read;
- ``counts``: what a worker held (its connections), readable by the parent after
  it died; the workers' state folder.
"""
