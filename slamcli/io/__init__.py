"""All slamcli disk formats (HDF5 schema v1, gzip + shuffle; see ``docs/schema.md``).

* :func:`write_dataset` / :func:`read_dataset`: simulator output (solver inputs + ground truth kept apart).
* :func:`write_result` / :func:`read_result`: solver output.
* :func:`dataset_hash`: content hash of a dataset (arrays + key metadata, not file bytes).
* :func:`atomic_path`: temp name in the destination directory + ``os.replace``.

Every reader validates the whole file and raises :class:`~slamcli.errors.SchemaError` with one line naming
the file, the group/field and the problem.
"""

from slamcli.io.atomic import atomic_path
from slamcli.io.dataset import dataset_hash, read_dataset, read_header, write_dataset
from slamcli.io.result import read_result, write_result
from slamcli.io.schema import DATASET_SCHEMA, RESULT_SCHEMA, SCHEMA_VERSION

__all__ = [
    "DATASET_SCHEMA",
    "RESULT_SCHEMA",
    "SCHEMA_VERSION",
    "atomic_path",
    "dataset_hash",
    "read_dataset",
    "read_header",
    "read_result",
    "write_dataset",
    "write_result",
]
