"""The reference state: rule file ``reference.smk``.

The unloaded shape found from an imaged posture, its round trip, a tumour tracked between
postures and the stiffness fitted to a second shape.
"""
