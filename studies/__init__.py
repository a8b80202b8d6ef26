"""Everything that measures, compares or reports: the layer above the physics and the surrogate.

The FE study (:mod:`studies.fe_benchmark`, :mod:`studies.fe_speed_accuracy`,
:mod:`studies.fe_reference`, :mod:`studies.stability`), the surrogate's study
(:mod:`studies.architecture`, :mod:`studies.surrogate_evaluation`,
:mod:`studies.surrogate_benchmark`, :mod:`studies.timing`), the machine the timings ran on
(:mod:`studies.machine`), the paper's published figures (:mod:`studies.paper`) and the
figures (:mod:`studies.figures`). It imports ``meshes``, ``fem`` and ``surrogate``; none of
them imports it.
"""
