"""``fovexp monitor``: the operator's live view of running sessions, a read-only web page
(docs/EXPERIMENT.md, "The operator's live view").

``view``: what the page shows, read from the files the runner writes (no web server needed);
``server``: the Starlette app and its guard against hostile requests; ``cli``: the command, and
``fovexp run --monitor``'s process beside the session; ``static/``: the page itself (plain HTML,
CSS and JavaScript, shipped in the wheel). It reads files on disk only: it never imports the
runner (``fovexp.experiment``), PsychoPy or moderngl, and shares no memory with a session.
The server's packages are the ``monitor`` extra (``pip install 'fovexp[monitor]'``).
"""
