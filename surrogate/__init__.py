"""JAX/optax Siamese-MLP surrogate of the FE breast model (domain + boundary networks).

:mod:`surrogate.config` holds the hyperparameters, :mod:`surrogate.data` turns the FE
dataset (read by :mod:`fem.dataset`) into network inputs, :mod:`surrogate.model` holds
the networks' shared pieces, :mod:`surrogate.structures` the structures (``pointwise``,
``separable``, ``pod``: each one's networks, forward pass, training and export, chosen by name
once), :mod:`surrogate.train` fits them,
:mod:`surrogate.checkpoint` saves and loads a model folder, :mod:`surrogate.predict`
queries a loaded model, :mod:`surrogate.fields` writes fields for ParaView,
:mod:`surrogate.cli` is the command line and :mod:`surrogate.exceptions` its errors.
"""
