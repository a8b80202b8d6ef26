"""JAX/optax Siamese-MLP surrogate of the FE breast model (domain + boundary networks).

:mod:`surrogate.config` holds the hyperparameters, :mod:`surrogate.data` loads the
FE dataset, :mod:`surrogate.model` defines the networks and the paper's loss,
:mod:`surrogate.train` fits them and :mod:`surrogate.predict` saves, loads and
queries a trained model.
"""
