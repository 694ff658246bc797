"""The canonical cache rendered in worker processes (data.prepare_workers): the same files as one
process, and a bad mesh file named with nothing half-written."""
import json

import numpy as np
import pytest
import trimesh

from datamodules.canonical import CanonicalDataModule, DataError, tosca


def _synth(path, **kw):
    return CanonicalDataModule.from_flat(str(path), image_size=32, n_subjects=4, n_poses=3, mesh_resolution=24, n_folds=2,
                               kinds=["humanoid", "quadruped"], seed=1, flow_targets=True, own_poses=1, **kw)


def test_workers_write_the_same_cache_as_one_process(tmp_path):
    one, two = _synth(tmp_path / "one"), _synth(tmp_path / "two", prepare_workers=2)
    one.prepare_data()
    two.prepare_data()
    m1, m2 = (json.loads((tmp_path / d / "manifest.json").read_text()) for d in ("one", "two"))
    assert m1["config_hash"] == m2["config_hash"]  # prepare_workers does not change the cache's identity
    assert m1["subjects"] == m2["subjects"] and len(m1["items"]) == 4
    for it in m1["items"]:
        with np.load(tmp_path / "one" / it["file"]) as a, np.load(tmp_path / "two" / it["file"]) as b:
            assert sorted(a.files) == sorted(b.files) and any(k.startswith("flow_") for k in a.files)
            for k in a.files:
                np.testing.assert_array_equal(a[k], b[k], err_msg=f"{it['file']}: {k}")
    two.setup()
    assert two.describe()["train"]["items"] > 0


def test_a_bad_mesh_file_stops_the_workers_with_its_name(tmp_path):
    cap = trimesh.creation.capsule(height=1.0, radius=0.2)
    root = tmp_path / "tosca"
    root.mkdir()
    for cls in ("cat", "dog", "wolf"):
        for pose in (0, 1, 2):
            tosca.write_off(root / f"{cls}{pose}.off", cap.vertices * (1 + 0.1 * pose), cap.faces)
    text = (root / "dog1.off").read_text().splitlines()
    (root / "dog1.off").write_text("\n".join(text[: len(text) // 3]))  # a truncated download
    dm = CanonicalDataModule.from_flat(str(tmp_path / "c"), source="tosca", root=str(root), image_size=32, split="pose",
                             n_folds=2, prepare_workers=2)
    with pytest.raises(DataError, match="dog1"):
        dm.prepare_data()
    assert not (tmp_path / "c" / "manifest.json").exists()
    assert not list((tmp_path / "c").rglob("*.tmp"))
