"""The participant's task: the adjustment of the paper's section 5.1 (:mod:`.trial`: the value,
the wheel, the blanking of one attempt; :mod:`.frameloop`: its frames; :mod:`.adjust`: the
trials in order, each until confirmed), the screens around trials (:mod:`.screens`: messages,
the quit confirmation, pauses, the lost tracker; :mod:`.sequence`: announcements and breaks;
:mod:`.operator`: the operator's form, checklist and console line), and the simulated
participant of dry runs (:mod:`.simulated_participant`); beside the adjustment, the forced-choice
task (:mod:`.forced_choice`, issue 30), its adaptive procedures (:mod:`.procedures`: QUEST+ and
constant stimuli, rebuilt from the logged answers) and its simulated observer
(:mod:`.simulated_observer`).

May import: ``fovexp`` (public API), :mod:`fovexp.results`, :mod:`fovexp.stimuli`,
:mod:`fovexp.experiment.interfaces`, and the rooms below it: ``protocol`` and ``trackers``.
What a task writes goes through the callables it is given, never through ``records``
(tests/test_layers.py).
"""
