"""The command line's output paths, checked in one place below every layer.

Every entry point that writes takes its output path through argparse's ``type=``
(:func:`output_file`, :func:`output_folder`), so a path that cannot be written stops it before
any work with ``error: argument ...: ...`` and exit status 2. Once its arguments are parsed it
hands its outputs and inputs to :func:`refuse_overwriting`, so that no output is one of its
inputs: the same file given twice, a file inside an input folder (a model's), the HDF5 data of
an input XDMF. :mod:`fem.arguments` gives the same functions to the layers above.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Iterable
from pathlib import Path


def output_folder(text: str) -> Path:
    """A folder to write into: absent (it is made) or a folder, not a file."""
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a file, not a folder to write into")
    return path


def output_file(text: str) -> Path:
    """A file to write, not a folder (its folder is made where missing, under a folder)."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder, not a file to write")
    above = next((p for p in path.parents if p.exists()), None)  # the folder made under
    if above is not None and not above.is_dir():
        raise argparse.ArgumentTypeError(f"the folder of {text} is a file"
                                         + ("" if above == path.parent else f" ({above})"))
    return path


def _same(a: Path, b: Path) -> bool:
    """Whether two paths name one file (by the file system where both exist: links too)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def overwritten(output: Path, inputs: Iterable[tuple[str, Path | None]]) -> str | None:
    """Why writing ``output`` would change one of ``inputs``, or None.

    An input folder (a model's) holds all its files; an input ``.xdmf`` its ``.h5`` beside it.

    Args:
        output: a file to write.
        inputs: ``(argument, path)`` of every input (None: not given).
    """
    target = output.resolve()
    for name, path in inputs:
        if path is None:
            continue
        path = Path(path)
        if _same(output, path):
            return f"{output} is an input ({name}: {path})"
        if path.is_dir() and path.resolve() in target.parents:
            return f"{output} lies in an input folder ({name}: {path})"
        if path.suffix.lower() == ".xdmf" and _same(output, path.with_suffix(".h5")):
            return f"{output} is the HDF5 data of an input ({name}: {path})"
    return None


def refuse_overwriting(parser: argparse.ArgumentParser, option: str, outputs: Iterable[Path],
                       inputs: Iterable[tuple[str, Path | None]]) -> None:
    """Stop the command (exit status 2, one line) if an output would change an input.

    Args:
        parser: the command's parser (its ``error`` prints the usage and the line).
        option: the output's argument, for the message (``-o/--output``).
        outputs: every file the command writes there (a page and the licence beside it).
        inputs: ``(argument, path)`` of every input (None: not given).
    """
    inputs = list(inputs)
    for output in outputs:
        why = overwritten(Path(output), inputs)
        if why is not None:
            parser.error(f"argument {option}: {why}: it would be overwritten; write elsewhere")
