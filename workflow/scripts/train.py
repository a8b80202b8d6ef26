"""Snakemake adapter: train the surrogate on the dataset and save it."""

import logging
from pathlib import Path

from surrogate.config import SurrogateConfig
from surrogate.data import load_dataset, write_json
from surrogate.predict import save_model
from surrogate.train import train_and_evaluate

logging.basicConfig(filename=snakemake.log[0], level=logging.INFO, force=True)

dataset = load_dataset(snakemake.input.dataset)
result = train_and_evaluate(dataset, SurrogateConfig.from_mapping(snakemake.params.surrogate))
save_model(Path(snakemake.output.model).parent, result, dataset)
write_json(snakemake.output.history, {"summary": result.summary(), "history": result.history})
