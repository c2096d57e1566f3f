"""``shacc report``: one self-contained HTML page of a sweep folder or an evaluate
file, checked in a real browser (Debian's ``chromium``, headless): every figure
decodes, the tables are there, nothing is loaded from outside and the script logs no
error; its numbers are the dataset's."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pandas as pd
import pytest

from geometry_precompute import InputError, shipped_scene_paths
from sweeps.analysis.report import FIGURE_WIDTH, evaluate_report, sweep_report
from sweeps.app.cli import main
from sweeps.config import load_config
from sweeps.distributed.runner import run_sweep

CONFIG = """
name = "report"
chunk = 2
[source]
kind = "random"
count = 4
tasks = [3, 4]
seed = 11
[settings]
start_grid = [2, 2]
user_noise = { uniform = [0.0, 0.4] }
[axes]
v_max = [0.15, 0.3]
shrink_step = [0.01, 0.02]
"""

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_browser = pytest.mark.skipif(
    CHROMIUM is None, reason="the browser test needs Debian's chromium package "
    "(apt-get install chromium); .ci/run installs it")


def browse(page: Path, tmp: Path) -> tuple[str, str]:
    """(the DOM after the page's scripts ran, chromium's log with console messages)."""
    profile = tmp / "chromium-profile"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
           "--disable-background-networking", "--disable-component-update",
           "--disable-sync", "--disable-extensions", f"--user-data-dir={profile}",
           "--enable-logging=stderr", "--v=0", "--virtual-time-budget=5000",
           "--dump-dom", page.resolve().as_uri()]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr[-2000:]
    return p.stdout, p.stderr


def check_in_browser(page: Path, tmp: Path) -> str:
    dom, log = browse(page, tmp)
    body = re.search(r"<body([^>]*)>", dom).group(1)
    figures = int(re.search(r'data-figures="(\d+)"', body).group(1))
    loaded = int(re.search(r'data-figures-loaded="(\d+)"', body).group(1))
    assert figures > 0 and loaded == figures
    # Every figure at least the chosen width (its natural width, read by the page).
    assert int(re.search(r'data-narrowest-figure="(\d+)"', body).group(1)) >= FIGURE_WIDTH
    # The page's own console: no uncaught error, no failed load.
    console = [ln for ln in log.splitlines() if "CONSOLE" in ln]
    assert not [ln for ln in console if "rror" in ln], console
    return dom


@pytest.fixture(scope="module")
def sweep_folder(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("report")
    cfg_path = tmp / "sweep.toml"
    cfg_path.write_text(CONFIG)
    out = tmp / "out"
    summary = run_sweep(load_config(cfg_path), out, tmp / "cache", workers=1, progress=False)
    assert summary["status"] == "complete"
    return out


def test_sweep_report_numbers_are_the_datasets(sweep_folder):
    html = sweep_report(sweep_folder, n_boot=500)
    scenes = pd.read_parquet(sweep_folder / "scenes")
    # Every point's and mode's mean success, as the pandas mean over its scenes.
    for (point, ), g in scenes.groupby(["point"]):
        for mode in ("baseline", "shrinking", "shacc"):
            mean = g[f"{mode}.success"].mean()
            row = re.search(rf"<tr><td class=\"l\">{point}</td><td class=\"l\">[^<]*</td>"
                            rf"<td class=\"l\">{mode}</td><td class=\"\">([0-9.]+) ", html)
            assert row and float(row.group(1)) == pytest.approx(mean, abs=5e-4)
    # Time, path and assistance per point and mode: the mean over scenes of the
    # scenes table's columns; the shares of one mode sum to one.
    for (point, ), g in scenes.groupby(["point"]):
        for mode in ("baseline", "shacc"):
            row = re.search(rf'<table class="time">.*?<tr><td class="l">{point}</td>'
                            rf'<td class="l">{mode}</td>((?:<td class="">[^<]*</td>)+)',
                            html, re.S)
            cells = [float(c.split()[0]) for c in re.findall(r'<td class="">([^<]*)</td>',
                                                               row.group(1))]
            assert cells[0] == pytest.approx(g[f"{mode}.time_mean"].mean(), abs=5e-3)
            assert cells[1] == pytest.approx(g[f"{mode}.path_length_mean"].mean(), abs=5e-4)
            assert sum(cells[2:]) == pytest.approx(1.0, abs=2e-3)
    # The population's draws, per point: success binned by the drawn noise.
    assert "Success against the drawn users" in html
    for point in scenes["point"].unique():
        assert f"point {point}: Direction noise (rad), as drawn: ShaCC" in html
    assert html.count('<table class="drawn">') == scenes["point"].nunique()
    # Nothing from outside the page.
    assert not re.search(r"(src|href)=\"(https?:)?//", html)
    # Per-point bars (few points), the assistance shares, two axes, two heat maps.
    assert html.count("<img") == 6
    check_layout(html)


def check_layout(html: str) -> None:
    """A headline first (a sentence per comparison with its interval), then figures,
    then tables (long ones folded); heat maps of success on 0-1, differences on a
    scale centred on 0."""
    head = re.search(r'<section class="headline">(.*?)</section>', html, re.S).group(1)
    sentences = re.findall(r"<li>(.*?)</li>", head)
    assert sentences[0].startswith("Success over ")
    assert any(re.match(r"ShaCC against the baseline: success [+-]\d\.\d{3} \[[+-]\d\.\d{3}, "
                        r"[+-]\d\.\d{3}\] \(paired, over \d+ scenes", s_) for s_ in sentences)
    assert html.index('<section class="headline">') < html.index("<figure") \
        < html.index("<table")
    assert html.rindex("<figure") < html.index("<table")  # every figure before
    for table in re.findall(r"(<details><summary>\d+ rows.*?</details>)", html, re.S):
        assert table.count("<tr>") > 12
    scales = re.findall(r'<figure class="heatmap" data-scale="([^"]+)" data-colormap="(\w+)"',
                        html)
    if scales:
        assert scales[0] == ("0.0,1.0", "viridis")
        lo, hi = map(float, scales[1][0].split(","))
        assert scales[1][1] == "RdBu" and lo == -hi and hi >= 0.05


@pytest.mark.browser
@needs_browser
def test_sweep_report_in_a_browser(sweep_folder, tmp_path):
    assert main(["report", str(sweep_folder)]) == 0
    page = sweep_folder / "report.html"
    dom = check_in_browser(page, tmp_path)
    for cls in ("modes", "paired", "tasks"):
        assert f'<table class="{cls}">' in dom
    assert "Provenance" in dom and "config_hash" in dom
    # The sweep still resumes with the report beside its tables.
    cfg = sweep_folder.parent / "sweep.toml"
    assert main(["sweep", str(cfg), "--out", str(sweep_folder), "--quiet",
                 "--cache", str(sweep_folder.parent / "cache")]) == 0


@pytest.mark.browser
@needs_browser
def test_evaluate_report_in_a_browser(tmp_path):
    scenes = [str(p) for p in shipped_scene_paths()[:3]]
    src = tmp_path / "run.jsonl"
    assert main(["evaluate", *scenes, "--json", str(src)]) == 0
    assert main(["report", str(src), "--out", str(tmp_path / "page.html")]) == 0
    dom = check_in_browser(tmp_path / "page.html", tmp_path)
    lines = [json.loads(x) for x in src.read_text().splitlines()]
    for d in lines:
        assert d["scene"] in dom
        for t in d["tasks_detail"]:
            assert t["id"] in dom
    assert '<table class="paired">' in dom
    check_layout(dom)


def test_report_refuses_what_it_cannot_read(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="scenes"):
        sweep_report(tmp_path / "empty")
    bad = tmp_path / "bad.jsonl"
    bad.write_text('{"not": "an evaluate line"}\n')
    with pytest.raises(InputError, match="line 1"):
        evaluate_report(bad)
    assert main(["report", str(tmp_path / "missing")]) == 2
    assert "no such" in capsys.readouterr().err
    assert not (tmp_path / "bad.html").exists()
