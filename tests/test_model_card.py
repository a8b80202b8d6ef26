"""A model card's training range is checked on load (issue 70).

``training_range: NaN`` ended in an AttributeError; ``C1_kPa: [NaN, NaN]`` or a reversed range
was taken, and every query then warned "outside [nan, nan]" or never warned. Each is refused by
name, by the loader of the whole model and by the card's reader.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

from surrogate.checkpoint import read_model_card
from surrogate.config import SurrogateConfig
from surrogate.exceptions import ModelFileError
from surrogate.predict import Surrogate
from tests.test_surrogate import dataset_path  # noqa: F401 (a fixture: a small dataset)

pytestmark = pytest.mark.unit

NAN = math.nan


@pytest.fixture(scope="module")
def model(dataset_path: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:  # noqa: F811
    """A tiny model of the small dataset, saved."""
    from fem.dataset import read_dataset
    from surrogate.checkpoint import save_model
    from surrogate.train import train_and_evaluate

    ds = read_dataset(dataset_path)
    result = train_and_evaluate(
        ds, SurrogateConfig(hidden_layers=1, width=4, max_epochs=1), progress=False)
    folder = tmp_path_factory.mktemp("card") / "model"
    save_model(folder, result, ds)
    return folder


def _spoiled(model: Path, tmp_path: Path, change: dict[str, Any] | float) -> Path:
    """A copy of ``model`` whose card's training range is ``change`` (a float: the whole)."""
    folder = tmp_path / "model"
    folder.mkdir()
    for path in model.iterdir():
        (folder / path.name).write_bytes(path.read_bytes())
    card = json.loads((folder / "model.json").read_text())
    if isinstance(change, dict):
        card["training_range"].update(change)
    else:
        card["training_range"] = change
    (folder / "model.json").write_text(json.dumps(card))  # NaN as JSON's NaN, as json writes
    return folder


@pytest.mark.parametrize("change, named", [
    (NAN, r"training_range is nan, not a mapping"),
    ({"C1_kPa": [NAN, NAN]}, r"training_range\.C1_kPa is \[nan, nan\], not \[low, high\]"),
    ({"C1_kPa": [5.0, 1.0]}, r"training_range\.C1_kPa is \[5\.0, 1\.0\], not \[low, high\]"),
    ({"C1_kPa": [1.0]}, r"training_range\.C1_kPa is \[1\.0\]"),
    ({"phi_deg": [0.0, NAN]}, r"training_range\.phi_deg\[1\] is nan, not a finite number"),
    ({"directions": [[0.0, "up"]]}, r"training_range\.directions\[0\] is \[0\.0, 'up'\]"),
    ({"unconverged": [[1.0, 0.0]]}, r"training_range\.unconverged\[0\] is \[1\.0, 0\.0\], "
                                    r"not 3 finite numbers"),
    ({"c1_by_direction": [[0.0, 0.0, 5.0, 1.0]]},
     r"training_range\.c1_by_direction\[0\]: its C1 range \[5\.0, 1\.0\]"),
    ({"tissues": {"fat": NAN}}, r"training_range\.tissues is \{'fat': nan\}"),
], ids=["nan", "C1 nan", "C1 reversed", "C1 one value", "phi nan", "direction text",
        "unconverged pair", "direction's C1 reversed", "tissue nan"])
def test_a_damaged_training_range_is_refused_by_name(
    model: Path, tmp_path: Path, change: dict[str, Any] | float, named: str
) -> None:
    folder = _spoiled(model, tmp_path, change)
    with pytest.raises(ModelFileError, match=rf"model: {named}"):
        Surrogate.load(folder)
    with pytest.raises(ModelFileError, match=rf"model\.json: {named}"):
        read_model_card(folder)


def test_the_training_range_as_saved_is_read(model: Path) -> None:
    loaded = Surrogate.load(model)
    assert loaded.training_range["C1_kPa"] == [1.0, 5.0]
    assert read_model_card(model)["training_range"] == loaded.training_range
