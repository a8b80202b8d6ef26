"""Everything that measures, compares or reports: the layer above the physics and the surrogate.

One room per study, named like its config section and rule file: the FE study
(:mod:`studies.fe_study`), the surrogate study (:mod:`studies.surrogate_study`), the reference
state (:mod:`studies.reference_state`) and the sweep's own study (:mod:`studies.sweep`). At the
top, what they share: the typed results (:mod:`studies.results`), the config's error
(:mod:`studies.config_errors`), the machine the timings ran on (:mod:`studies.timing_hygiene`), the
paper's published figures (:mod:`studies.paper`) and the figures (:mod:`studies.figures`). It
imports ``meshes``, ``fem`` and ``surrogate``; none of them imports it.
"""
