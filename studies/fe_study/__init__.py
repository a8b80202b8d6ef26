"""The FE study: config section ``fe_study``, rule file ``fe_study.smk``.

The solver's variants against a reference, its timing and speed against accuracy, where Newton
fails over the sweep, whether an equilibrium is stable, the fold, self-contact, the skin and the
corpus of anatomies.
"""
