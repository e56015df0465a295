"""What a session writes and reads back: the crash-safe logs (:mod:`.logs`) and their rows
(:mod:`.rows`), the session file (:mod:`.sessionfile`), the choice between a new session and
the one it resumes (:mod:`.resume`), the participant folder's lock (:mod:`.lock`) and ID
(:mod:`.participant_id`), the results disk's free space (:mod:`.diskspace`), the live status
file ``fovexp monitor`` reads (:mod:`.live`), and the logs of one run, opened and closed
together (:mod:`.runlogs`). The formats themselves are :mod:`fovexp.results.format`, shared
with the analysis.

May import: ``fovexp`` (public API), :mod:`fovexp.results`, :mod:`fovexp.experiment.interfaces`,
and every room below it: ``protocol``, ``trackers``, ``tasks``, ``display``
(tests/test_layers.py).
"""
