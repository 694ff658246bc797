"""The quality demo's driver (``scripts/demo_quality.py``, run by ``scripts/demo_quality.sh``): the distorted
versions it writes, the ranked table it makes of ``lit3d-score --json`` outputs, and its one-line errors."""
import importlib.util
import json

import numpy as np
import pytest
import trimesh
from tests.helpers.paths import REPO

SCRIPT = REPO / "scripts" / "demo_quality.py"


@pytest.fixture(scope="module")
def demo():
    spec = importlib.util.spec_from_file_location("demo_quality", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def prepared(demo, tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    return out, demo.prepare(out)


def test_prepare_writes_the_reference_and_each_distortion(demo, prepared):
    out, pairs = prepared
    assert [n for n, _ in pairs] == list(demo.DISTORTIONS)
    lines = (out / "pairs.tsv").read_text().splitlines()
    assert [ln.split("\t")[0] for ln in lines] == ["reference", *demo.DISTORTIONS]
    ref = trimesh.load(out / "meshes" / "reference.obj", process=False)
    for name, path in pairs:
        mesh = trimesh.load(path, process=False)
        same = len(mesh.vertices) == len(ref.vertices) and np.allclose(mesh.vertices, ref.vertices)
        assert not same, f"{name}: not distorted"


def test_report_ranks_by_score_and_bad_score_files_are_one_line(demo, prepared, monkeypatch, capsys):
    out, pairs = prepared
    scores = out / "scores"
    scores.mkdir(exist_ok=True)
    config = {"render": {"size": 64}, "styles": ["clay_studio"]}
    for i, (name, _) in enumerate(pairs):
        feats = {"ssim/clay_studio/flat": 0.5, "psnr/clay_studio/flat": 20.0, "chamfer": 0.01}
        (scores / f"{name}.json").write_text(json.dumps({"overall_score": i / 10, "features": feats, "config": config}))
    drawn = []
    monkeypatch.setattr(demo, "figure", lambda *a: drawn.append(a))  # the renders are lit3d-score's own tests
    text = demo.report(out)
    ranked = [ln.split("|")[2].strip(" `") for ln in text.splitlines() if ln.startswith("| ") and ln[2].isdigit()]
    assert ranked == [f"{n}.obj" for n, _ in reversed(pairs)]  # the highest score first
    assert (out / "results.md").read_text() == text and len(drawn) == 1

    bad = scores / f"{pairs[0][0]}.json"
    for content, message in [("{not json", "not lit3d-score --json output (Expecting"),
                             ('{"overall_score": 1}', "not lit3d-score --json output (no features, config)"),
                             (None, f"no lit3d-score output for '{pairs[0][0]}'")]:
        bad.unlink(missing_ok=True)
        if content is not None:
            bad.write_text(content)
        assert demo.main(["report", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"demo_quality.py report: error: {bad}: {message}") and "\n" not in err, err
    (out / "pairs.tsv").write_text("noise\tx.obj\n")
    assert demo.main(["report", str(out)]) == 2
    assert "pairs.tsv: not the list that 'prepare' writes" in capsys.readouterr().err
