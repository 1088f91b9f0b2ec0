"""scripts/fuzz_envs.py: the reliability record it writes, and the rule that a partial run keeps a full record."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import settings

from envs.fuzzing import ALL_IDS, PROPERTIES
from scripts import fuzz_envs


def test_fuzz_script_writes_the_record_and_keeps_other_sections(tmp_path: Path) -> None:
    out = tmp_path / "reliability.json"
    out.write_text(json.dumps({"preemption": {"kept": True}}))
    before = settings.default.max_examples
    record = fuzz_envs.main(["--ids", "ProofOfMemory-v0", "--max-examples", "2", "--out", str(out)])
    assert settings.default.max_examples == before, "the caller's profile is restored"
    saved = json.loads(out.read_text())
    assert saved == json.loads(json.dumps(record)) and saved["preemption"] == {"kept": True}
    section = saved["fuzzed_environments"]
    assert set(section["per_id"]) == {"ProofOfMemory-v0"} and section["properties"] == list(PROPERTIES)
    cases = section["per_id"]["ProofOfMemory-v0"]["cases"]
    assert cases["faces_agree"] >= 1 and cases["invalid_refused"] >= 1 and section["failures_total"] == 0
    assert section["max_examples"] == 2 and section["git_revision"] and section["versions"]["hypothesis"]
    assert section["found_and_fixed"] and "fuzz_envs.py" in section["command"]
    assert fuzz_envs.partial_reasons(saved), "one id of eleven is a partial record"


def test_a_partial_run_never_replaces_a_full_record(tmp_path: Path) -> None:
    out = tmp_path / "reliability.json"
    full = {"per_id": dict.fromkeys(ALL_IDS, {}), "properties": list(PROPERTIES), "profile": "long"}
    out.write_text(json.dumps({"fuzzed_environments": full}))
    assert not fuzz_envs.partial_reasons(json.loads(out.read_text()))
    with pytest.raises(SystemExit):
        fuzz_envs.main(["--ids", "ProofOfMemory-v0", "--max-examples", "1", "--out", str(out)])
    assert json.loads(out.read_text())["fuzzed_environments"] == full
