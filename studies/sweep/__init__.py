"""The sweep's own study: config section ``sweep``, rule file ``sweep.smk``.

The adaptive rounds' record and the check of their error estimate at cases no round chose.
"""
