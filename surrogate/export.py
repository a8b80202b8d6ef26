"""A trained surrogate exported for a web page: what the browser needs to predict on its own.

:func:`export_web` writes everything :meth:`surrogate.predict.Surrogate.predict` uses, as a
JSON-ready mapping: the networks' weights, the standardised material points, the per-point
output gain, the query encoding and the training range that decides when a query is an
extrapolation. Arrays travel as base64 of little-endian ``float32``/``int32``/``uint8`` with
their shape, so a page decodes them into typed arrays without parsing millions of numbers.
``report/viewer/app.js`` holds the forward pass that reads it; the viewer's test checks it
against :meth:`Surrogate.predict` at every material point.
"""

from __future__ import annotations

import base64
from typing import Any

import numpy as np

from surrogate.predict import Surrogate
from surrogate.structures import structure_for

FORMAT = "breast-surrogate-web"
VERSION = 1


def encode_array(values: np.ndarray, dtype: str) -> dict[str, Any]:
    """``{dtype, shape, data}``: the array as base64 of its little-endian bytes."""
    array = np.ascontiguousarray(values, dtype=np.dtype(dtype).newbyteorder("<"))
    return {"dtype": dtype, "shape": list(array.shape),
            "data": base64.b64encode(array.tobytes()).decode("ascii")}


def decode_array(encoded: dict[str, Any]) -> np.ndarray:
    """Inverse of :func:`encode_array`."""
    raw = base64.b64decode(encoded["data"])
    dtype = np.dtype(encoded["dtype"]).newbyteorder("<")
    return np.frombuffer(raw, dtype=dtype).reshape(encoded["shape"])


def export_web(model: Surrogate) -> dict[str, Any]:
    """The surrogate as the web page's forward pass reads it.

    Per network part (``domain``, and ``boundary`` where the rib points have a network of
    their own or share the domain's): the indices of its points, its layers
    ``[{W, b}, ...]`` (the first layer's rows: the three point coordinates, then the four case
    features) and its points' output gain (the exact-Dirichlet factor times the network's
    displacement unit, mm). Rib points of a part-less model (``exact`` mode) are zero. The
    last layer of a ``gravity_linear`` model has nine outputs, the matrix that the page
    contracts with the query's gravity direction.

    A ``separable`` model's point networks take the three coordinates alone (with their Fourier
    features, ``point_frequencies``, where the model has them) and give 3 × ``modes`` outputs,
    and the model carries its ``branch`` layers: the page computes the
    fields once per point, as :class:`Surrogate` does at load, and per query evaluates the branch
    and weighs the fields with its outputs. The page carries weights, not fields, so its size
    does not grow with the modes times the points.

    A ``pod`` model has no point networks: its one part carries its ``modes`` at the points
    instead of layers, (points, 3, ``modes``), and the page weighs them as a separable model's
    fields (without the 1/√modes of a separable model's sum). Its rib points are zero.

    Raises:
        ValueError: for a ``pod`` model asked at more points than its nodes
            (:meth:`Surrogate.at`), which holds no modes at them.
    """
    config, norm = model.config, model.normalisation
    structure = structure_for(config)
    factor = np.ones(len(model.X)) if model.point_factor is None else model.point_factor
    parts: dict[str, dict[str, Any]] = {}
    members = {"domain": np.flatnonzero(~model.boundary)}
    net = structure.boundary_network()
    if net is not None and model.boundary.any():
        members["boundary"] = np.flatnonzero(model.boundary)
    for part, index in members.items():
        parts[part] = {
            "points": encode_array(index, "int32"),
            "gain": encode_array(factor[index] * norm.u_scale, "float32"),
            **structure.web_part(model, index, "domain" if part == "domain" else net),
        }
    checks = model.trained.range_checks()
    return {
        "format": FORMAT,
        "version": VERSION,
        "architecture": config.architecture,
        "activation": config.activation,
        "boundary": config.boundary,
        "output_form": config.output_form,
        "structure": structure.name,
        **structure.web_fields(model),
        "n_points": int(len(model.X)),
        "X_m": encode_array(model.X, "float32"),
        "points_standardised": encode_array(norm.points(model.X), "float32"),
        "rib": encode_array(model.boundary, "uint8"),
        "encoding": {
            "c1": norm.c1_encoding,
            "c1_min": norm.c1_min,
            "c1_max": norm.c1_max,
            "output_scaling": norm.output_scaling,
            "c1_ref": norm.c1_ref,
        },
        "parts": parts,
        "training_range": checks,
    }


def encode_layers(layers: Any) -> list[dict[str, Any]]:
    """A network's layers as the page reads them: ``[{W, b}, ...]``, each encoded."""
    return [
        {"W": encode_array(np.asarray(W), "float32"), "b": encode_array(np.asarray(b), "float32")}
        for W, b in layers
    ]
