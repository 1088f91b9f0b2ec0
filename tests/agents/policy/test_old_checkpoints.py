"""A checkpoint written before agents/ was split into rooms (tests/data/checkpoints/) still loads, evaluates and
resumes, with the records the code that wrote it made of it: moving code moved nothing that a checkpoint holds."""

from __future__ import annotations

import io
import json
import math
import pickle
import shutil
import zipfile
from pathlib import Path

import pytest

from agents.config import Schedule
from agents.policy.checkpoint import checked_payload, latest_checkpoint, load_policy, read_checkpoint, write_checkpoint
from scripts import evaluate as evaluate_script
from scripts import train as train_script

DATA = next(p for p in Path(__file__).resolve().parents if p.name == "tests") / "data" / "checkpoints"
RUN = DATA / "tiny_gru"
EXPECTED = DATA / "expected"


@pytest.fixture
def run_copy(tmp_path: Path) -> Path:
    """The committed run, copied: resuming writes into its directory."""
    return Path(shutil.copytree(RUN, tmp_path / RUN.name))


class _Anything:
    """Whatever the pickle builds, built as nothing: only the names it asks for matter here."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        pass

    def __call__(self, *args: object, **kwargs: object) -> _Anything:
        return _Anything()

    def __setstate__(self, state: object) -> None:
        pass

    def __setitem__(self, key: object, value: object) -> None:
        pass

    def append(self, value: object) -> None:
        pass

    def extend(self, values: object) -> None:
        pass


class _NameRecorder(pickle.Unpickler):
    """An unpickler that records ``module.name`` of every global the pickle refers to and imports none of them."""

    def __init__(self, data: bytes) -> None:
        super().__init__(io.BytesIO(data))
        self.names: set[str] = set()

    def find_class(self, module: str, name: str) -> type:
        self.names.add(f"{module}.{name}")
        return _Anything

    def persistent_load(self, pid: object) -> object:  # torch's tensor storages
        return None


def pickled_globals(path: Path) -> set[str]:
    """``module.name`` of every class or function the checkpoint's pickle refers to (what unpickling imports)."""
    with zipfile.ZipFile(io.BytesIO(checked_payload(path))) as archive:
        data = archive.read(next(name for name in archive.namelist() if name.endswith("data.pkl")))
    recorder = _NameRecorder(data)
    recorder.load()
    return recorder.names


def test_the_pickle_reader_finds_a_class_of_this_project(tmp_path: Path) -> None:
    path = write_checkpoint(tmp_path / "update_0000001.pt", {"schedule": Schedule(1.0)})
    assert {name for name in pickled_globals(path) if name.startswith("agents.")}


def test_the_old_checkpoint_refers_to_no_module_of_this_project() -> None:
    found = pickled_globals(latest_checkpoint(RUN))
    assert found, "no global found: the pickle was not read"
    assert not {name for name in found if name.split(".")[0] in ("agents", "envs", "scripts")}, found


def test_the_old_checkpoint_loads_as_a_policy() -> None:
    policy = load_policy(RUN)
    assert (policy.update, policy.step) == (2, 128)
    assert read_checkpoint(policy.checkpoint)["config"]["model"]["memory"] == "gru"


def test_the_old_checkpoint_evaluates_to_the_records_its_code_made(tmp_path: Path) -> None:
    out = tmp_path / "evaluation"
    assert evaluate_script.main(["--run", str(RUN), "--out", str(out), "--no-progress"]) == 0
    assert (out / "episodes.csv").read_text() == (EXPECTED / "evaluation_episodes.csv").read_text()


def test_the_old_checkpoint_resumes_for_its_last_update_as_its_code_did(run_copy: Path) -> None:
    assert train_script.main(["--resume", str(run_copy)]) == 0
    assert (run_copy / "training.csv").read_text() == (EXPECTED / "resumed_training.csv").read_text()
    assert (run_copy / "eval" / "episodes.csv").read_text() == (EXPECTED / "resumed_eval_episodes.csv").read_text()
    state = read_checkpoint(latest_checkpoint(run_copy))
    expected = json.loads((EXPECTED / "resumed_model.json").read_text())
    assert (state["update"], state["global_step"]) == (expected["update"], expected["global_step"])
    assert list(state["model"]) == list(expected["model"])
    for name, tensor in state["model"].items():
        found = {"sum": float(tensor.double().sum()), "abs_sum": float(tensor.double().abs().sum())}
        for key, value in expected["model"][name].items():
            assert math.isclose(found[key], value, rel_tol=1e-5, abs_tol=1e-7), (name, key, found[key], value)
