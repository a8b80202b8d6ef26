"""The ``mesh`` config section as one validated object, and the stage that acts on it."""

from __future__ import annotations

import json
import logging
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from meshes.configfile import ConfigFileError, read_config_file
from meshes.exceptions import GeometryError, reject_unknown
from meshes.image import ImageSpec
from meshes.importing import ImportSpec, write_imported_mesh
from meshes.parametric import BreastGeometry
from meshes.sizing import MeshSize
from meshes.tags import Boundary

log = logging.getLogger(__name__)

SOURCES = ("parametric", "file", "image")


@dataclass(frozen=True, slots=True)
class MeshConfig:
    """Where the geometry comes from and how it is meshed.

    Attributes:
        source: ``parametric`` (the OCC breast of :class:`BreastGeometry`), ``file``
            (a user's surface or volume mesh, :class:`ImportSpec`) or ``image`` (a
            segmentation's label volume, :class:`meshes.image.ImageSpec`).
        geometry: parameters of the parametric breast (ignored for an import).
        size: element sizes and order.
        file: what to import (required for ``file``).
        image: what to mesh (required for ``image``).
    """

    source: str = "parametric"
    geometry: BreastGeometry = field(default_factory=BreastGeometry)
    size: MeshSize = field(default_factory=MeshSize)
    file: ImportSpec | None = None
    image: ImageSpec | None = None

    def __post_init__(self) -> None:
        if self.source not in SOURCES:
            raise GeometryError(f"mesh.source must be one of {SOURCES}, got {self.source!r}")
        if self.source == "file" and self.file is None:
            raise GeometryError("mesh.source is 'file' but mesh.file is missing")
        if self.source == "image" and self.image is None:
            raise GeometryError("mesh.source is 'image' but mesh.image is missing")

    @property
    def imported(self) -> ImportSpec | ImageSpec | None:
        """What the geometry is imported from (``file`` or ``image``), or None (parametric)."""
        return {"file": self.file, "image": self.image}.get(self.source)

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> MeshConfig:
        """Build from the ``mesh`` config mapping.

        ``mesh.fixed`` is the solver's (``fem.parameters.FixedBoundaries``) and is not
        read here; any other unknown key is rejected by name.
        """
        reject_unknown(values, {"source", "geometry", "size", "file", "image", "fixed"},
                       "mesh key(s)")
        source = values.get("source", "parametric")
        file_values = values.get("file")
        config = cls(
            source=source,
            geometry=BreastGeometry.from_mapping(values.get("geometry") or {}),
            size=MeshSize.from_mapping(size_for_source(source, values.get("size") or {})),
            # the file section may stay in the config while the parametric source is used
            file=ImportSpec.from_mapping(file_values) if file_values and source == "file" else None,
            image=(ImageSpec.from_mapping(values["image"])
                   if values.get("image") and source == "image" else None),
        )
        if config.imported is not None:
            # An imported mesh names only the surfaces its rules select (the rest is skin):
            # clamping a surface no rule names would fail in every solve, so stop here.
            unnamed = [
                name
                for name, spec in (values.get("fixed") or {}).items()
                if spec != "none"
                and Boundary.from_label(name) not in config.imported.rules()
                and Boundary.from_label(name) != Boundary.SKIN
            ]
            if unnamed:
                raise GeometryError(
                    f"mesh.fixed clamps {', '.join(unnamed)}, but mesh.{source}.surfaces has no "
                    "rule that names it: add a rule (group, plane or surface) for it"
                )
        return config

    def input_files(self) -> list[str]:
        """Files the mesh is built from (none for the parametric source)."""
        return self.imported.input_files() if self.imported is not None else []


def size_for_source(source: str, values: Mapping[str, Any]) -> dict[str, Any]:
    """``mesh.size`` as :class:`MeshSize` takes it for ``source``.

    The mound's size is the parametric breast's (an import meshes at ``global_size``): for an
    import it is capped at ``global_size``, so that a finer ``global_size`` alone, as a user
    writes it for an image-resolution surface, is no error about a mound the file has not.
    """
    values = dict(values)
    if source not in ("file", "image"):
        return values
    default = MeshSize()
    mound = values.get("mound_size", default.mound_size)
    finest = values.get("global_size", default.global_size)
    numbers = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (mound, finest))
    return {**values, "mound_size": min(mound, finest)} if numbers else values


def make_mesh(
    config: MeshConfig, xdmf_path: str | Path, quality_path: str | Path, png_path: str | Path
) -> dict[str, Any]:
    """Build (or import) the tagged mesh; write XDMF, the quality JSON and the PNG.

    Returns:
        The quality report that was written.
    """
    if config.source == "parametric":
        from meshes.build import write_parametric_mesh

        report = write_parametric_mesh(config.geometry, config.size, xdmf_path, png_path)
    else:
        assert config.imported is not None  # __post_init__ guarantees it
        report = write_imported_mesh(config.imported, config.size, xdmf_path, png_path)
    target = Path(quality_path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")  # renamed into place
    tmp.write_text(json.dumps(report, indent=2))
    os.replace(tmp, target)
    return report


def read_mesh_config(path: str | Path) -> MeshConfig:
    """The ``mesh`` section of a config file, typed; a file without one is named.

    Raises:
        ConfigFileError: as :func:`meshes.configfile.read_config_file`, or for a file
            without a ``mesh`` section.
        GeometryError, MeshInputError: for a ``mesh`` section that is not valid.
    """
    values = read_config_file(path)
    section = values.get("mesh")
    if not isinstance(section, dict):
        raise ConfigFileError(f"{path}: the config file has no mesh section")
    return MeshConfig.from_mapping(section)
