"""The MLflow store: which one runs log to, and a check that it can be used before any work.

MLflow 3 refuses the old ./mlruns file store; the default here is a local sqlite file.
"""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, cast

from pipeline.common.fingerprints import files_digest, settings_digest

if TYPE_CHECKING:
    from mlflow.data.meta_dataset import MetaDataset
    from mlflow.tracking import MlflowClient

DEFAULT_TRACKING_URI = "sqlite:///mlflow.db"


def import_mlflow():
    """mlflow, imported only when tracking is asked for (it is slow to import), with its telemetry
    off unless the user set MLFLOW_DISABLE_TELEMETRY (runs here log to a local store), and without
    the INFO lines a new store prints (its tables and schema migrations, a new experiment)."""
    os.environ.setdefault("MLFLOW_DISABLE_TELEMETRY", "true")
    import mlflow

    for name in ("alembic", "mlflow.store.db.utils", "mlflow.tracking.fluent"):
        logging.getLogger(name).setLevel(logging.WARNING)
    return mlflow


def resolve_tracking_uri(uri: str | None = None) -> str:
    """The CLI's value, else MLFLOW_TRACKING_URI, else the local sqlite store."""
    return uri or os.environ.get("MLFLOW_TRACKING_URI") or DEFAULT_TRACKING_URI


SERVER_SCHEMES = ("http", "https", "databricks", "postgresql", "mysql", "mssql")


def check_tracking_uri(uri: str | None = None, timeout_s: float = 5.0) -> str:
    """The resolved store, checked before any work: ValueError in one line when it cannot be used.

    MLflow itself only finds out when the first run is logged, after a whole benchmark,
    and then retries for minutes (a server that does not answer, a read-only folder).
    """
    uri = resolve_tracking_uri(uri)
    scheme = uri.split(":", 1)[0].lower() if ":" in uri else ""
    if scheme == "sqlite":
        if not uri.startswith("sqlite:///"):
            raise ValueError(
                f"tracking store {uri!r}: a sqlite store is sqlite:///RELATIVE/PATH.db or sqlite:////ABSOLUTE/PATH.db"
            )
        path = Path(uri[len("sqlite:///") :])
        folder = path.parent  # "." for a bare file name
        if not folder.is_dir():
            raise ValueError(f"tracking store {uri!r}: folder {folder} does not exist")
        try:  # sqlite writes its journal beside the database: the folder must take new files
            tempfile.TemporaryFile(dir=folder).close()
        except OSError as error:
            raise ValueError(f"tracking store {uri!r}: cannot write in {folder} ({error.strerror})") from None
        if path.exists() and not os.access(path, os.W_OK):
            raise ValueError(f"tracking store {uri!r}: {path} is not writable")
        return uri
    if scheme in ("http", "https"):
        import urllib.error
        import urllib.request

        try:
            urllib.request.urlopen(f"{uri.rstrip('/')}/health", timeout=timeout_s).close()
        except urllib.error.HTTPError:
            return uri  # something answers; MLflow reports what it thinks of it
        except (urllib.error.URLError, OSError, ValueError) as error:
            reason = getattr(error, "reason", error)
            raise ValueError(f"tracking store {uri!r}: no MLflow server answers ({reason})") from None
        return uri
    if scheme in SERVER_SCHEMES:
        return uri
    raise ValueError(
        f"tracking store {uri!r} is not one MLflow 3 can log to here: use sqlite:///mlflow.db (the default), "
        "an http(s):// tracking server or a database URI"
    )


def dvc_hash(folder: str | Path) -> str | None:
    """DVC's recorded hash of `folder` when a stage of its DVC project outputs it, else None (not
    in a DVC project, or not a stage's output)."""
    from dvc.exceptions import DvcException, NotDvcRepoError
    from dvc.repo import Repo

    folder = Path(folder).resolve()
    existing = next(path for path in (folder, *folder.parents) if path.is_dir())
    try:
        with Repo(Repo.find_root(str(existing))) as repo:
            outs = repo.find_outs_by_path(str(folder))
    except (NotDvcRepoError, DvcException):  # no project, or no stage outputs it
        return None
    return next((out.hash_info.value for out in outs if out.hash_info and out.hash_info.value), None)


def maze_set_input(
    folder: str | Path, context: str = "evaluation", digest: str | None = None
) -> tuple[MetaDataset, dict[str, str]]:
    """The MLflow dataset input of the maze set (or data set) `folder`: named by the folder,
    its digest DVC's hash where a stage made it (else `digest`, else a digest of its files), its
    source the folder; returns (dataset, tags) for `mlflow.log_input(dataset, context, tags)`."""
    import warnings

    import_mlflow()  # telemetry off first
    from mlflow.data.dataset_source_registry import resolve_dataset_source
    from mlflow.data.meta_dataset import MetaDataset

    folder = Path(folder)
    recorded = dvc_hash(folder)
    with warnings.catch_warnings():  # a local path reads as two kinds of the same source
        warnings.simplefilter("ignore", UserWarning)
        source = resolve_dataset_source(str(folder.resolve()))
    name = folder.as_posix() if not folder.is_absolute() else folder.name
    dataset = MetaDataset(  # type: ignore[abstract]  # mlflow marks `profile` abstract; Dataset is no ABC
        source=source, name=name, digest=recorded or digest or files_digest([folder])
    )
    tags = {"dvc_hash": recorded or "none (not a DVC output here)", "context": context}
    return dataset, tags


def log_generated_maze_set(name: str, settings: dict, context: str = "training") -> None:
    """Record a maze set drawn in the run itself (no folder outlives it) as a dataset input of
    the active MLflow run: named `name`, its digest that of the `settings` it was drawn from
    (the generator's, with the seed), which are its source."""
    mlflow = import_mlflow()
    from mlflow.data.code_dataset_source import CodeDatasetSource
    from mlflow.data.meta_dataset import MetaDataset

    source = CodeDatasetSource({k: str(v) for k, v in settings.items()})
    dataset = MetaDataset(  # type: ignore[abstract]  # mlflow marks `profile` abstract; Dataset is no ABC
        source=source, name=name, digest=settings_digest(settings)
    )
    mlflow.log_input(dataset, context=context, tags={"dvc_hash": "none (drawn in the run)", "context": context})


def log_maze_set(
    folder: str | Path, context: str = "evaluation", run_id: str | None = None, client: MlflowClient | None = None
) -> None:
    """Record the maze set `folder` as a dataset input of the active MLflow run (or of `run_id`
    through `client`, for a run Lightning's logger holds)."""
    dataset, tags = maze_set_input(folder, context)
    mlflow = import_mlflow()
    if run_id is None:
        mlflow.log_input(dataset, context=context, tags=tags)
        return
    from mlflow.entities import DatasetInput, InputTag

    input_tags = [InputTag("mlflow.data.context", context)] + [
        InputTag(k, v) for k, v in tags.items() if k != "context"
    ]
    cast("MlflowClient", client).log_inputs(run_id, datasets=[DatasetInput(dataset._to_mlflow_entity(), input_tags)])
