"""`gym-fetch view`: the static page's files, and the page itself in a real headless Chromium
(it loads from disk without errors, its videos play, a click on a demo switches the plots)."""

from __future__ import annotations

import io
import json
import pathlib
import shutil
import time

import h5py
import numpy as np
import pytest

pytest.importorskip("av")
pytest.importorskip("PIL")

from fetch.cli import main  # noqa: E402
from fetch.dataset import open_dataset  # noqa: E402
from fetch.dataset.render.video import read_video  # noqa: E402

SIZE = 64


@pytest.fixture(scope="module")
def dataset(reach_demos: pathlib.Path, tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    """The two Reach demos, the second made invalid (an action outside [-1, 1])."""
    copy = tmp_path_factory.mktemp("view") / "demos"
    shutil.copytree(reach_demos, copy)
    with open_dataset(copy) as ds:
        path, group = ds.demo_file("demo_1")
    with h5py.File(path, "r+") as f:
        f[group]["actions"][0, 0] = 2.0
    return copy


@pytest.fixture(scope="module")
def page(dataset: pathlib.Path, tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    out = tmp_path_factory.mktemp("page") / "report"
    assert main(["view", str(dataset), "--out", str(out), "--size", str(SIZE)]) == 0
    return out


def summary_of(page: pathlib.Path) -> dict:
    html = (page / "index.html").read_text()
    tag = '<script id="summary" type="application/json">'
    start = html.index(tag) + len(tag)
    return json.loads(html[start:html.index("</script>", start)])


def test_page_files(page: pathlib.Path, dataset: pathlib.Path) -> None:
    summary = summary_of(page)
    rows = {d["name"]: d for d in summary["demos"]}
    assert list(rows) == ["demo_0", "demo_1"] and summary["env_id"] == "Reach-v2"
    assert rows["demo_0"]["valid"] and not rows["demo_1"]["valid"]
    assert "actions outside [-1, 1]" in rows["demo_1"]["problem"]
    with open_dataset(dataset) as ds:
        for name, row in rows.items():
            arrays, attrs = ds.arrays(name), ds.attrs(name)
            assert (row["length"], row["seed"], row["device"], row["success"]) == \
                (attrs["num_samples"], attrs["seed"], attrs["device"], attrs["success"])
            frames, rate = read_video(page / row["video"])
            assert frames.shape == (attrs["num_samples"] + 1, SIZE, SIZE, 3) and rate == 25
            script = (page / row["data"]).read_text()
            prefix = f'window.FetchView.receive("{name}", '
            assert script.startswith(prefix)
            series = json.loads(script[len(prefix):script.rindex(");")])
            assert np.allclose(np.array(series["actions"]).T, arrays["actions"], rtol=1e-4, atol=1e-6)
            assert np.allclose(np.array(series["obs"]["grip_pos"]).T[:-1], arrays["obs/observation"][:, :3], rtol=1e-4)
    assert "http" not in (page / "index.html").read_text().replace("http://www.w3.org/2000/svg", "")  # no network


@pytest.mark.parametrize(("args", "message"), [
    (["--size", "63"], "--size must be an even number of pixels"),
    (["--camera", "ceiling"], "unknown camera 'ceiling'; known: "),
    (["--workers", "0"], "--workers must be at least 1"),
])
def test_bad_input(dataset: pathlib.Path, tmp_path: pathlib.Path, capsys: pytest.CaptureFixture[str],
                   args: list[str], message: str) -> None:
    assert main(["view", str(dataset), "--out", str(tmp_path / "r"), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err
    assert not list(tmp_path.iterdir())


def test_an_existing_page_needs_force(page: pathlib.Path, dataset: pathlib.Path, tmp_path: pathlib.Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "r"
    shutil.copytree(page, out)
    (out / "mine.txt").write_text("keep")
    assert main(["view", str(dataset), "--out", str(out), "--size", str(SIZE)]) == 2
    assert "already exists and is not empty" in capsys.readouterr().err and (out / "mine.txt").exists()
    assert main(["view", str(dataset), "--out", str(out), "--size", str(SIZE), "--force"]) == 0
    assert not (out / "mine.txt").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["r"]


def png_pixels(data: bytes) -> np.ndarray:
    from PIL import Image

    with Image.open(io.BytesIO(data)) as image:
        return np.asarray(image.convert("RGB"))


def test_page_in_headless_chromium(page: pathlib.Path, tmp_path: pathlib.Path) -> None:
    import cdp

    with cdp.open_page(page / "index.html", tmp_path) as browser:
        assert browser.wait_for("window.FetchView && FetchView.state.plotted") == "demo_0"
        rows = browser.evaluate("[...document.querySelectorAll('tr.demo')].map(r => r.dataset.demo)")
        assert rows == ["demo_0", "demo_1"]
        assert browser.evaluate("document.querySelectorAll('#summary-plots svg').length") == 3
        first_plot = browser.evaluate("document.querySelector('#plots polyline').getAttribute('points')")
        # each plot's legend sits above its plot area, clear of the curves
        overlaps = browser.evaluate("""[...document.querySelectorAll('#plots svg.plot')].flatMap(svg => {
            const area = svg.querySelector('rect').getBoundingClientRect();
            return [...svg.querySelectorAll('text.legend')].filter(t => t.getBoundingClientRect().bottom > area.top)
              .map(t => svg.dataset.title + ': ' + t.textContent); })""")
        assert browser.evaluate("document.querySelectorAll('#plots text.legend').length") >= 4 and overlaps == []
        # the videos play: each has presented new frames (the count goes on across loops) and the picture changes
        played = ("[...document.querySelectorAll('video')].map(v => [v.getVideoPlaybackQuality().totalVideoFrames,"
                  " v.paused, v.readyState])")
        before = browser.evaluate(played)
        rect = browser.evaluate("JSON.parse(JSON.stringify(document.getElementById('detail-video')"
                                ".getBoundingClientRect()))")
        clip = {k: rect[k] for k in ("x", "y", "width", "height")}
        first = png_pixels(browser.screenshot(clip))
        for _ in range(40):  # a demo ends holding still: look until another frame shows
            time.sleep(0.05)
            if not np.array_equal(png_pixels(browser.screenshot(clip)), first):
                break
        else:
            raise AssertionError("the selected demo's video showed the same picture for 2 s")
        browser.wait_for(f"({played})" + ".every((v, i) => v[0] >= " + json.dumps([b[0] for b in before]) + "[i] + 3)")
        after = browser.evaluate(played)
        assert all(not paused and ready >= 2 for _, paused, ready in after), (before, after)
        full = browser.screenshot()
        (tmp_path / "page.png").write_bytes(full)
        pixels = png_pixels(full)
        assert pixels.shape[:2] == (900, 1200) and len(np.unique(pixels.reshape(-1, 3), axis=0)) > 50
        # a real click on the second row switches the plots to it
        box = browser.evaluate("JSON.parse(JSON.stringify(document.getElementById('row-demo_1')"
                               ".getBoundingClientRect()))")
        browser.click(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        assert browser.wait_for("FetchView.state.plotted === 'demo_1' && document.body.dataset.plotted")
        assert browser.evaluate("document.getElementById('row-demo_1').classList.contains('selected')")
        assert browser.evaluate("document.getElementById('detail-title').textContent").startswith("demo_1:")
        assert "actions outside" in browser.evaluate("document.getElementById('detail-problem').textContent")
        assert browser.evaluate("document.querySelector('#plots polyline').getAttribute('points')") != first_plot
        assert browser.evaluate("FetchView.state.errors") == []
        assert browser.errors() == []


def test_a_demo_that_cannot_be_read_is_a_row_without_video(reach_demos: pathlib.Path, tmp_path: pathlib.Path) -> None:
    copy = tmp_path / "demos"
    shutil.copytree(reach_demos, copy)
    with open_dataset(copy) as ds:
        path, _ = ds.demo_file("demo_0")
    path.unlink()
    assert main(["view", str(copy), "--out", str(tmp_path / "r"), "--size", str(SIZE)]) == 0
    rows = {d["name"]: d for d in summary_of(tmp_path / "r")["demos"]}
    assert not rows["demo_0"]["valid"] and rows["demo_0"]["video"] is None and rows["demo_0"]["data"] is None
    assert "cannot be read" in rows["demo_0"]["problem"]
    assert rows["demo_1"]["valid"] and (tmp_path / "r" / rows["demo_1"]["video"]).is_file()


def test_the_files_own_problems_are_on_the_page_and_counted(reach_demos: pathlib.Path, tmp_path: pathlib.Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """A `total` off by one and a mask naming a missing demo are no one demo's problem: the page said
    "0 invalid" and showed nothing."""
    copy = tmp_path / "d"
    shutil.copytree(reach_demos, copy)
    with h5py.File(copy / "demos.hdf5", "r+") as f:
        f["data"].attrs["total"] = int(f["data"].attrs["total"]) + 1
        names = [*f["mask/valid"][()], b"demo_9"]
        del f["mask/valid"]
        f["mask/valid"] = names
    capsys.readouterr()
    assert main(["view", str(copy), "--out", str(tmp_path / "r"), "--size", str(SIZE)]) == 0
    assert "0 invalid, 2 problem(s) of the file" in capsys.readouterr().out
    problems = summary_of(tmp_path / "r")["problems"]
    assert len(problems) == 2 and any("total" in p for p in problems) and any("demo_9" in p for p in problems)


def test_a_strangers_markup_in_a_dataset_stays_text_in_chromium(reach_demos: pathlib.Path,
                                                               tmp_path: pathlib.Path) -> None:
    """A dataset whose path holds `<!--<script>` (the page's script never ran, the page said "0 invalid")
    and whose attributes hold markup: the page runs, shows the strings as text and runs none of them."""
    import cdp

    copy = tmp_path / "x<!--<script>y"
    shutil.copytree(reach_demos, copy)
    markup = '<img src=x onerror="window.pwned=1"></script><script>window.pwned=2</script>'
    with open_dataset(copy) as ds:
        path, group = ds.demo_file("demo_0")
    with h5py.File(path, "r+") as f:
        f[group].attrs["device"] = markup
    with h5py.File(copy / "demos.hdf5", "r+") as f:  # a problem of the file, shown above the table
        f["data"].attrs["total"] = int(f["data"].attrs["total"]) + 1
    out = tmp_path / "report"
    assert main(["view", str(copy), "--out", str(out), "--size", str(SIZE)]) == 0
    html = (out / "index.html").read_text()
    assert "<!--<script" not in html and markup not in html
    with cdp.open_page(out / "index.html", tmp_path) as browser:
        assert browser.wait_for("window.FetchView && FetchView.state.plotted") == "demo_0"
        assert browser.evaluate("typeof window.pwned") == "undefined"
        assert browser.evaluate("document.querySelectorAll('img').length") == 0
        assert browser.evaluate("document.querySelector('#row-demo_0 td.device').textContent") == markup
        assert "x<!--<script>y" in browser.evaluate("document.getElementById('subtitle').textContent")
        assert "data.attrs['total']" in browser.evaluate("document.getElementById('file-problems').textContent")
        assert browser.evaluate("FetchView.state.errors") == []
