"""The overview page of a run (index.html, index.md, report.html per scenario), as a reader opens it.

The browser test renders the page in headless Chromium (Debian's chromium and chromium-driver, which
.ci/run installs when missing) and checks what a person would see: the scoreboard, every image loaded,
no broken link. Without a browser it skips and says why.
"""

import json
import os
import shutil
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlparse

import numpy as np
import pytest

from fusionbench.bench import scenarios
from fusionbench.bench.experiment import run_scenario, write_scenario_report
from fusionbench.experiments.overview import GOOD_FACTOR, _flag_diverged, grade, headline, write_overview
from fusionbench.files import provenance
from fusionbench.files.pages import write_page

TINY = Path(__file__).parent / "data" / "tiny-jump.toml"  # static, reference noise x100 from 40 to 60 s


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """A two-scenario run written as `fusionbench run all` writes it: reports, pages and the overview."""
    out = tmp_path_factory.mktemp("run")
    results = []
    for scn, methods in ((scenarios.get("static-34n"), ["coarse", "coarse-i0"]), (scenarios.load(TINY), None)):
        res = run_scenario(scn, methods=methods, runs=2, seed=0, quick=True, progress=False)
        res.metrics["provenance"] = provenance.collect(seed=0, runs=2, duration_s=res.metrics["duration_s"],
                                                      quick=True, wall_s=1.0)
        path = write_scenario_report(res, out / scn.name)
        write_page(path)
        results.append((scn, res.metrics, path))
    write_overview(out, results, wall_total=2.0)
    return out, results


class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links, self.images, self.cells = [], [], []
        self._in_board = False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "a":
            self.links.append(a["href"])
        if tag == "img":
            self.images.append(a["src"])
        if tag == "table" and a.get("id") == "scoreboard":
            self._in_board = True
        if tag == "td" and self._in_board:
            self.cells.append(a.get("class"))

    def handle_endtag(self, tag):
        if tag == "table":
            self._in_board = False


def _parse(path):
    p = _Links()
    p.feed(Path(path).read_text(encoding="utf-8"))
    return p


def test_headline_of_an_alignment_is_the_azimuth_rms_about_the_limit():
    rng = np.random.default_rng(1)
    phi_u = rng.normal(-3.0, 2.0, 50)  # final azimuth errors of 50 runs, arcmin; limit -3.67
    stat = {"mean": float(phi_u.mean()), "std": float(phi_u.std())}
    m = {"scenario": "s", "limits_arcmin": {"U": -3.67}, "methods": {"x": {"final_error_arcmin": {"U": stat}}}}
    col = headline("alignment", m)
    assert col.values["x"][0] == pytest.approx(np.sqrt(np.mean((phi_u + 3.67) ** 2)))
    assert "limit -3.67" in col.note
    m["methods"]["y"] = {"final_error_arcmin": {"U": {"mean": 4000.0, "std": 10.0}}}
    m["diverged"] = ["y"]
    col = _flag_diverged(headline("alignment", m), m)
    assert col.values["y"][1].endswith("(diverged)") and grade(col, "y") == "poor" and grade(col, "x") == "good"


def test_headlines_of_navigation_and_calibration_and_conformance():
    nav = {"scenario": "n", "reduction_percent": 41.0, "methods": {
        "fixed": {"window_rmse_arcmin": {"level": 2.0}}, "adaptive": {"window_rmse_arcmin": {"level": 1.18}}}}
    col = headline("navigation", nav)
    assert col.values["adaptive"] == (1.18, "1.180") and "41.0 %" in col.note
    assert grade(col, "adaptive") == "good" and grade(col, "fixed") == "fair"  # 2.0 / 1.18 = 1.7 > GOOD_FACTOR
    assert 2.0 / 1.18 > GOOD_FACTOR
    cal = {"scenario": "c", "methods": {"ekf": {"groups": {
        "gyro bias": {"max_abs_error_mean": 0.0005, "paper_below": 0.001},
        "accel bias": {"max_abs_error_mean": 3.0, "paper_below": 1.0},
        "axis angles": {"max_abs_error_mean": 9.0, "paper_below": None}}}}}
    col = headline("calibration", cal, experiment="platform-rolling")
    assert col.values["ekf"] == (3.0, "1/2; 3 (accel bias)") and grade(col, "ekf") == "fair"
    conf = {"scenario": "m", "methods": {}, "cells": {"a": {
        "c1": {"status": "pass", "efficiency_U": 1.2, "efficiency_max": 1.5},
        "c2": {"status": "fail", "efficiency_U": 2.0, "efficiency_max": 1.5},
        "c3": {"status": "not claimed"}}}}
    col = headline("conformance", conf, experiment="conformance")
    assert col.values["a"][1] == "1/2; 2.00" and grade(col, "a") == "poor"


def test_overview_links_every_scenario_and_figure_that_exists(report):
    out, results = report
    page = _parse(out / "index.html")
    names = [m["scenario"] for _, m, _ in results]
    for n in names:
        assert f"{n}/report.html" in page.links and f"{n}/report.md" in page.links
    for target in page.links + page.images:
        assert (out / unquote(target)).is_file(), target
    # the scoreboard: a row per method, a cell per scenario; coarse ran in both
    assert len(page.cells) == 3 * (1 + len(names))  # coarse, coarse-i0, kf
    for scn_page in (out / n / "report.html" for n in names):
        sub = _parse(scn_page)
        assert sub.images, f"{scn_page} shows no figure"
        for target in sub.links + sub.images:
            assert (scn_page.parent / unquote(target)).is_file(), (scn_page, target)
    md = (out / "index.md").read_text()
    assert "tiny-jump/report.md" in md and "phiU RMS in the jump window 40-60 s" in md
    board = json.loads((out / "static-34n" / "metrics.json").read_text())["provenance"]
    html_text = (out / "index.html").read_text()
    assert board["date_utc"] in html_text and board["command"] in html_text and "http" not in html_text


def test_report_files_are_readable_by_others_as_the_umask_allows(report):
    out, _ = report
    mask = os.umask(0)
    os.umask(mask)
    files = [p for p in out.rglob("*") if p.is_file() and p.suffix != ".toml"]
    assert {p.suffix for p in files} >= {".png", ".json", ".md", ".html"}
    assert {oct(p.stat().st_mode & 0o777) for p in files} == {oct(0o666 & ~mask)}


def _browser():
    """A headless Chromium driven by selenium, or the reason there is none."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        return None, "selenium is not installed (pip install -e '.[test]')"
    if not (chromium and driver):
        return None, "no chromium/chromedriver on PATH: install Debian's chromium and chromium-driver (.ci/run does)"
    opts = webdriver.ChromeOptions()
    opts.binary_location = chromium
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--window-size=1400,1000"):
        opts.add_argument(flag)
    return webdriver.Chrome(service=Service(executable_path=driver), options=opts), None


def test_overview_renders_in_a_real_browser(report):
    out, results = report
    browser, why = _browser()
    if browser is None:
        pytest.skip(why)
    try:
        pages = [out / "index.html"] + [p.with_suffix(".html") for _, _, p in results]
        for page in pages:
            browser.get(page.as_uri())
            broken = browser.execute_script(
                "return Array.from(document.images).filter(i => !i.complete || i.naturalWidth === 0)"
                ".map(i => i.getAttribute('src'))")
            assert broken == [], f"{page}: images not loaded {broken}"
            for href in browser.execute_script("return Array.from(document.links).map(a => a.href)"):
                target = urlparse(href)
                assert target.scheme == "file", f"{page}: a link leaves the folder: {href}"
                assert Path(unquote(target.path)).is_file(), f"{page}: broken link {href}"
        browser.get((out / "index.html").as_uri())
        board = browser.find_element("id", "scoreboard")
        assert board.is_displayed() and board.size["height"] > 50
        text = board.text
        for method in ("coarse", "coarse-i0", "kf"):
            assert method in text
        assert "static-34n" in text and "tiny-jump" in text
        browser.save_screenshot(str(out / "index-screenshot.png"))
    finally:
        browser.quit()
