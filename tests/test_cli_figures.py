"""Every PNG the command line writes is a figure to read: axes with units, a legible size. The figures are
inspected as matplotlib objects while the commands write them (the `figures_drawn` fixture)."""
import re
from pathlib import Path

from conftest import axes_without_units

from thermo_ddp.cli import main

ELBOW = Path(__file__).resolve().parents[1] / "data" / "elbow"
RECORDINGS = [str(ELBOW / "static_3a.csv"), str(ELBOW / "biceps.csv")]


def _check(figures, count):
    assert len(figures) == count
    for fig in figures:
        assert axes_without_units(fig) == []
        width_px = fig.get_figwidth() * fig.dpi
        assert width_px <= 1600


def test_diagnosis_figure_shows_every_recording_legibly(tmp_path, figures_drawn):
    many = []  # four recordings (the old figure dropped the fourth): the two shipped ones and copies
    for k, source in enumerate(RECORDINGS * 2):
        many.append(tmp_path / f"{k}_{Path(source).name}")
        many[-1].write_bytes(Path(source).read_bytes())
    assert main(["diagnose", *map(str, many), "--plot", str(tmp_path / "d.png"), "-q"]) == 0
    _check(figures_drawn, 1)
    fig, = figures_drawn
    titles = [ax.get_title() for ax in fig.axes if ax.get_visible() and ax.get_title()]
    assert len(titles) == len(many) and "all 4 recordings" in fig.texts[0].get_text()
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        assert ax.yaxis.label.get_size() >= 9 and min(t.get_size() for t in ax.get_legend().get_texts()) >= 9
        labels = {t.get_text() for t in ax.get_legend().get_texts()}
        shaded = [p for p in ax.patches if p.get_alpha() and p.get_alpha() < 1]
        assert not shaded or any("mismatch" in t or "unexplained" in t for t in labels)  # every shade named
        assert len(re.findall(r"\[[^\]]+\]", ax.get_ylabel())) == 1  # one unit per axis: A and rad/s apart
    ylabels = [ax.get_ylabel() for ax in fig.axes if ax.get_visible()]
    assert "current [A]" in ylabels and "speed [rad/s]" in ylabels
    assert (tmp_path / "d.png").stat().st_size > 10_000


def test_validate_plan_compare_figures_have_units(tmp_path, figures_drawn):
    model = tmp_path / "m.toml"
    assert main(["identify", *RECORDINGS, "--write-model", str(model)]) == 0
    assert main(["validate", *RECORDINGS, "--model", str(model), "--plot", str(tmp_path / "v.png")]) == 0
    assert main(["plan", "--limit-c", "140", "--hold-s", "5", "--plot", str(tmp_path / "p.png")]) == 0
    assert main(["compare", "--hold-s", "10", "--plot", str(tmp_path / "c.png")]) == 0
    _check(figures_drawn, 3)


def test_mechanical_diagnosis_figure_has_units(emps_csv, tmp_path, figures_drawn):
    assert main(["diagnose", str(emps_csv), "--physics", "mechanical", "--plot", str(tmp_path / "m.png")]) == 0
    _check(figures_drawn, 1)


def test_sweep_figure_has_units(tmp_path, figures_drawn):
    assert main(["sweep", "--runs", "2", "--short", "--workers", "1", "--plot", str(tmp_path / "s.png")]) == 0
    _check(figures_drawn, 1)
