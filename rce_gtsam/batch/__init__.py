"""Many recordings at once on Dask: ``rce batch MANIFEST --out DIR`` / :func:`run`.

>>> from rce_gtsam import batch
>>> result = batch.run("manifest.csv", "out/batch")          # a LocalCluster, one worker per core
>>> result.summary[["id", "zone", "kappa", "verdict"]]        # = out/batch/summary.csv

Modules: :mod:`~rce_gtsam.batch.manifest` (the CSV and its validation), :mod:`~rce_gtsam.batch.options`
(shared settings, input fingerprints), :mod:`~rce_gtsam.batch.process` (one recording = one Dask task),
:mod:`~rce_gtsam.batch.runner` (the cluster and the loop), :mod:`~rce_gtsam.batch.summary`,
:mod:`~rce_gtsam.batch.figures` and :mod:`~rce_gtsam.batch.recording` (what the batch writes at the end).
"""

from .manifest import Manifest, Recording, load_manifest
from .options import BatchOptions
from .process import Outcome
from .runner import BatchResult, default_workers, run

__all__ = ["BatchOptions", "BatchResult", "Manifest", "Outcome", "Recording", "default_workers", "load_manifest",
           "run"]
