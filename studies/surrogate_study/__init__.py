"""The surrogate study: config section ``surrogate_study``, rule file ``surrogate.smk``.

The architectures compared, the held-out and off-grid errors, the timing, the postures and the
warnings' coverage.
"""
