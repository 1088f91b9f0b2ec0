"""scripts/plot.py on synthetic results: the figures it writes and the errors it gives for bad input."""

from __future__ import annotations

from pathlib import Path

import pytest
from matplotlib.image import imread

from agents.analysis.results import EPISODE_COLUMNS
from scripts import plot
from tests.support.synthetic_results import episode_rows, write_csv, write_results

FIGURES = ["curves.pdf", "curves.png", "final.pdf", "final.png"]


def assert_readable(out: Path) -> None:
    """curves and final (and, from records of several tasks, across_tasks), written atomically."""
    names = sorted(path.name for path in out.iterdir())
    assert [name for name in names if not name.startswith("across_tasks.")] == FIGURES, "no temporary file left"
    for name in ("curves.png", "final.png"):
        image = imread(out / name)
        assert image.ndim == 3 and image.shape[0] > 200 and image.shape[1] > 200 and image.std() > 0
    for name in ("curves.pdf", "final.pdf"):
        data = (out / name).read_bytes()
        assert data.startswith(b"%PDF-") and data.rstrip().endswith(b"%%EOF") and len(data) > 1000


def test_plot_writes_png_and_pdf(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    first = write_results(tmp_path / "a", methods=("ppo", "gru"))
    second = write_results(tmp_path / "b", methods=("stack4",), seed=1, training=False)
    out = tmp_path / "figures"
    assert plot.main([str(first), str(second), "--out", str(out), "--reps", "200"]) == 0
    assert_readable(out)
    captured = capsys.readouterr()
    assert "no training.csv in" in captured.err and str(second) in captured.err
    lines = captured.out.splitlines()
    assert lines[0].split() == ["method", "task", "step", "iqm", "low", "high", "runs", "episodes"]
    assert {line.split()[0] for line in lines[1:10]} == {"gru", "ppo", "stack4"}
    written = [line for line in lines if line.startswith("wrote ")]  # curves, final and, for 2 tasks, across_tasks
    assert sorted(Path(line.split()[1]).name for line in written) == sorted(
        f"{stem}.{fmt}" for stem in ("curves", "final", "across_tasks") for fmt in ("png", "pdf")
    )


def test_plot_another_column(tmp_path: Path) -> None:
    directory = write_results(tmp_path / "a", methods=("gru",), training=False)
    out = tmp_path / "figures"
    assert plot.main([str(directory), "--out", str(out), "--column", "metric_reference", "--reps", "100"]) == 0
    assert_readable(out)


def bad_inputs(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    (tmp_path / "empty").mkdir()
    rows = episode_rows(methods=("gru",), runs=1, steps=(10,), seeds=2, repetitions=1)
    write_csv(
        tmp_path / "nometric" / "episodes.csv",
        [{k: v for k, v in r.items() if k != "metric"} for r in rows],
        [c for c in EPISODE_COLUMNS if c != "metric"],
    )
    write_results(tmp_path / "fine", methods=("gru",), training=False)
    return {
        "missing directory": (tmp_path / "nowhere", "nowhere does not exist"),
        "no episodes.csv": (tmp_path / "empty", "empty has no episodes.csv"),
        "missing column": (tmp_path / "nometric", "lacks the column(s) metric"),
    }


@pytest.mark.parametrize("case", ["missing directory", "no episodes.csv", "missing column"])
def test_bad_input_is_a_clear_error(case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    directory, message = bad_inputs(tmp_path)[case]
    out = tmp_path / "figures"
    assert plot.main([str(tmp_path / "fine"), str(directory), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err
    assert not out.exists(), "nothing written"


def test_unknown_column_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    directory = write_results(tmp_path / "a", methods=("gru",), training=False)
    assert plot.main([str(directory), "--out", str(tmp_path / "f"), "--column", "coins"]) == 2
    assert "error: no column 'coins' in episodes.csv" in capsys.readouterr().err


def test_usage_errors() -> None:
    with pytest.raises(SystemExit):
        plot.main(["--out", "x"])  # no results directory
    with pytest.raises(SystemExit):
        plot.main(["somewhere"])  # no --out


def test_zoom_fits_the_metric_axis_to_the_data(tmp_path: Path) -> None:
    directory = write_results(tmp_path / "a", methods=("ppo",), training=False)  # PPO's scores stay below 0.6
    for name, flags in (("fixed", []), ("zoomed", ["--zoom"])):
        assert plot.main([str(directory), "--out", str(tmp_path / name), "--reps", "50", *flags]) == 0
        assert_readable(tmp_path / name)
    for figure in ("curves.png", "final.png"):
        assert (tmp_path / "fixed" / figure).read_bytes() != (tmp_path / "zoomed" / figure).read_bytes(), figure
