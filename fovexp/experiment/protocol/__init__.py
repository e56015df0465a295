"""A protocol and the study it belongs to: the YAML's schema and its loading, the plan of
trials, the values a protocol takes from earlier experiments (:mod:`.spec`), what a protocol
means where it is silent (:mod:`.defaults`), and a lab's study folder, ``fovexp init``
(:mod:`.study`).

May import: ``fovexp`` (public API), :mod:`fovexp.results`, :mod:`fovexp.stimuli`; no other
room of the runner (tests/test_layers.py).
"""
