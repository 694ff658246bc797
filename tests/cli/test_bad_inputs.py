"""Real bad files (and bad options) give one line naming the file and the problem.

One table, :data:`CASES`: ``(id, write, entry, words)``. ``write(tmp_path)`` writes the bad
file(s) and returns ``(argument, named)``: what the entry point gets and the file (or option)
the message must name. ``entry(arg, ctx)`` calls one entry point and returns an
:class:`Outcome`:

- console entry points (``lit3d-score`` ``main([...])``, the Hydra mains ``lit3d-train`` /
  ``lit3d-eval`` / ``lit3d-data`` in-process, and :func:`run_cli` on a composed config; two
  cases as real subprocesses) must exit non-zero with exactly one line on stderr, starting
  with ``error:`` (``lit3d-score: error:`` for lit3d-score, argparse's style);
- library loaders (``to_mesh``, ``load_grid``, ``convert_pair``, the canonical depth cache, the MOS
  readers) raise their own exception type with a one-line message. Every case: the line names the
  file (or option), holds the expected words, no "Traceback". Beyond the table: :mod:`test_bad_inputs_runs`.
"""
from __future__ import annotations

import os
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh

from datamodules.cache import DataError
from datamodules.quality.mos import MosDataError, read_liris_epfl
from datamodules.completion.recgan import convert_pair, load_grid
from lit3d.cli.common import run_cli
from lit3d.render.convert import ShapeError, to_mesh
from tests.helpers.bad_files import _file, _npz, _dir, _missing, PLY_HEAD, GARBAGE, BOX, _pair, _depth, _mos, _option, _ckpt
from tests.helpers.files import liris_epfl
from tests.helpers.runs import BIN, REPO
from tests.helpers.entry_points import Ctx, Outcome, data_cli, eval_cli, train_cli







# ----------------------------------------------------------------------------- entry points
def score(arg, ctx: Ctx) -> Outcome:
    """``lit3d-score GOOD.obj BAD`` in-process (bad shapes fail before any rendering)."""
    from lit3d.cli.score import main

    ref = ctx.tmp / "ref.obj"
    trimesh.creation.box().export(ref)
    code = main([str(ref), str(arg), "--size", "64", "--no-cache"])
    return Outcome(code, ctx.capsys.readouterr().err)


def _raises(exc_type: type[BaseException], fn: Callable, *args) -> Outcome:
    with pytest.raises(exc_type) as info:
        fn(*args)
    return Outcome(type(info.value).__name__, f"error: {info.value}")


def mesh_loader(arg, ctx):
    return _raises(ShapeError, to_mesh, arg)


def grid_loader(arg, ctx):
    return _raises(DataError, load_grid, arg)


def pair_converter(arg, ctx):
    return _raises(DataError, convert_pair, arg, 8, 8, 4)


def depth_cache(dm, ctx):
    return _raises(DataError, dm.setup)


def mos_reader(root, ctx):
    return _raises(MosDataError, read_liris_epfl, root)




def _run_cli(fn_path: str, config_name: str, overrides: Callable[[Any], list[str]]):
    """:func:`run_cli` (what every Hydra main calls) on a config composed in-process."""
    def entry(arg, ctx: Ctx) -> Outcome:
        from lit3d.runtime.build import import_object

        cfg = ctx.compose(overrides(arg), config_name=config_name)
        with pytest.raises(SystemExit) as info:
            run_cli(import_object(fn_path), cfg)
        return Outcome(info.value.code, ctx.capsys.readouterr().err)
    entry.__name__ = f"run_cli({fn_path.rsplit('.', 1)[1]})"
    return entry


eval_ckpt = _run_cli("lit3d.cli.evaluate.evaluate", "eval", lambda p: [f"ckpt_path={p}", "task=canonical"])
eval_ckpt_any_task = _run_cli("lit3d.cli.evaluate.evaluate", "eval", lambda p: [f"ckpt_path={p}"])
eval_no_ckpt = _run_cli("lit3d.cli.evaluate.evaluate", "eval", lambda _: [])
train_resume = _run_cli("lit3d.cli.train.train", "train", lambda p: ["logger=none", f"ckpt_path={p}"])
train_overrides = _run_cli("lit3d.cli.train.train", "train", lambda o: ["logger=none", *o.split()])


def _subprocess(prog: str, extra: Callable[[Path], list[str]] = lambda tmp: []):
    """The installed console script in a subprocess (the real process: exit status, stderr)."""
    def entry(arg, ctx: Ctx) -> Outcome:
        env = {k: v for k, v in os.environ.items() if k != "HYDRA_FULL_ERROR"}
        env.update(WANDB_MODE="offline", WANDB_SILENT="true")
        args = [str(BIN / prog), *str(arg).split(), f"hydra.run.dir={ctx.tmp}/run", *extra(ctx.tmp)]
        res = subprocess.run(args, cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
        return Outcome(res.returncode, res.stderr)
    entry.__name__ = f"{prog} (subprocess)"
    return entry


def _liris_missing_column(tmp: Path):
    root = liris_epfl(tmp / "liris", rows=[("Model", "Rating"), ("Armadillo_noise_1", 3)])
    return f"task=quality data=liris_epfl data.root={root}", str(root / "MOS_GeneralPurpose.xlsx")


# ----------------------------------------------------------------------------- the table
CASES = [
    # meshes
    ("mesh-empty-file", _file("empty.obj", b""), score, ["empty file"]),
    ("mesh-zero-faces", _file("nofaces.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"), score, ["no faces", "3 vertices"]),
    ("mesh-nan-vertex", _file("nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n"), score, ["NaN or inf"]),
    ("mesh-inf-vertex-ply", _file("inf.ply", PLY_HEAD + "0 0 0\ninf 0 0\n0 1 0\n3 0 1 2\n"), mesh_loader,
     ["NaN or inf"]),
    ("mesh-all-vertices-identical", _file("same.obj", "v 1 1 1\nv 1 1 1\nv 1 1 1\nf 1 2 3\n"), score,
     ["degenerate", "all vertices identical"]),
    ("mesh-face-index-past-end-obj", _file("past.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n"), score,
     ["face indices out of range"]),
    ("mesh-face-index-past-end-ply", _file("past.ply", PLY_HEAD + "0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n"), mesh_loader,
     ["face indices out of range", "of 3"]),
    ("mesh-face-index-past-end-off", _file("past.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n"), mesh_loader,
     ["face index outside the range"]),
    ("mesh-garbage-ply", _file("garbage.ply", GARBAGE), score, ["unreadable ply file"]),
    ("mesh-garbage-obj", _file("garbage.obj", GARBAGE), score, ["no geometry in file"]),
    ("mesh-garbage-stl", _file("garbage.stl", GARBAGE), mesh_loader, ["no geometry in file"]),
    ("mesh-is-a-directory", _dir("adir.ply"), score, ["a folder, not a file"]),
    ("mesh-missing", _missing("missing.obj"), score, ["no such file"]),
    # voxel grids (3D-RecGAN++ loader and lit3d-score)
    ("voxels-no-arr_0-key", _npz("nokey.npz", voxels=BOX), grid_loader, ["missing key 'arr_0'", "voxels"]),
    ("voxels-no-arrays-score", _npz("none.npz"), score, ["holds no arrays"]),
    ("voxels-string-dtype", _npz("str.npz", arr_0=np.full((8, 8, 8, 1), "x")), grid_loader, ["dtype <U1"]),
    ("voxels-string-dtype-score", _npz("str.npz", arr_0=np.full((8, 8, 8, 1), "x")), score, ["dtype <U1"]),
    ("voxels-complex-dtype", _npz("cx.npz", arr_0=BOX.astype(np.complex64)), grid_loader, ["complex64"]),
    ("voxels-complex-dtype-score", _npz("cx.npz", arr_0=BOX.astype(np.complex64)), score, ["complex64"]),
    ("voxels-float-half", _npz("half.npz", arr_0=np.full((8, 8, 8, 1), 0.5, np.float32)), grid_loader,
     ["values in [0.5, 0.5]", "expected int8 occupancy"]),
    ("voxels-float-half-score", _npz("half.npz", arr_0=np.full((8, 8, 8, 1), 0.5, np.float32)), score,
     ["voxel grid is empty"]),
    ("voxels-nan", _npz("nan.npz", arr_0=np.full((8, 8, 8, 1), np.nan, np.float32)), grid_loader, ["NaN or inf"]),
    ("voxels-wrong-ndim", _npz("ndim.npz", arr_0=np.ones((8, 8), np.int8)), grid_loader,
     ["shape (8, 8)", "expected (Dx, Dy, Dz, 1)"]),
    ("voxels-wrong-ndim-score", _npz("ndim5.npz", arr_0=np.ones((2, 8, 8, 8, 2), np.int8)), score,
     ["expected a 3-D grid"]),
    ("voxels-not-a-zip", _file("corrupt.npz", GARBAGE), grid_loader, ["unreadable .npz"]),
    ("voxels-all-empty-target", _pair(BOX, np.zeros_like(BOX), "target"), pair_converter, ["all-empty grid"]),
    ("voxels-all-empty-score", _npz("empty.npz", arr_0=np.zeros_like(BOX)), score, ["voxel grid is empty"]),
    ("voxels-input-target-shape-mismatch", _pair(BOX, np.ones((8, 8, 9, 1), np.int8), "input"), pair_converter,
     ["differs from its target", "(8, 8, 9)"]),
    # depth images in the canonical cache (read_subject / depth_image_problem, via setup())
    ("depth-nan", _depth(lambda d, m: (np.where(m, np.nan, 0).astype(np.float16), m)), depth_cache,
     ["depth_1_0", "contains NaN or inf"]),
    ("depth-all-background", _depth(lambda d, m: (np.zeros_like(d), np.zeros_like(m))), depth_cache,
     ["depth_1_0", "all background"]),
    ("depth-wrong-size", _depth(lambda d, m: (d[:16, :16], m[:16, :16])), depth_cache,
     ["depth_1_0", "shape (16, 16), expected (32, 32)"]),
    # MOS spreadsheets
    ("mos-missing-score-column", _mos(rows=[("Model", "Rating"), ("Armadillo_noise_1", 3)]), mos_reader,
     ["no sheet has both a model-name column", "score column"]),
    ("mos-score-out-of-range", _mos(rows=[("Model", "MOS"), ("Armadillo_noise_1", 11.5)]), mos_reader,
     ["row 3", "score 11.5 outside the published range 0.0..10.0"]),
    ("mos-row-names-missing-mesh", _mos(missing={"Dyno_noise_2"}), mos_reader,
     ["'Dyno_noise_2'", "no mesh file named"]),
    ("mos-missing-column-lit3d-data", _liris_missing_column, _subprocess("lit3d-data",
     lambda tmp: [f"paths.data_dir={tmp}/data"]), ["no sheet has both a model-name column"]),
    # configs and options
    ("train-unknown-experiment", _option("experiment=nope"), train_cli,
     ["experiment=nope", "no such experiment config", "known: body_demo, body_regressor, canonical_animals"]),
    ("train-unknown-task", _option("task=nope"), train_cli, ["task=nope", "known: body, canonical, completion, quality"]),
    ("eval-unknown-experiment", _option("experiment=nope"), eval_cli,
     ["experiment=nope", "known: body_demo, body_regressor, canonical_animals"]),
    ("data-unknown-experiment", _option("experiment=nope"), data_cli,
     ["experiment=nope", "known: body_demo, body_regressor, canonical_animals"]),
    ("data-unknown-data", _option("data=nope"), data_cli, ["data=nope", "known: ", "canonical_synth"]),
    ("train-tosca-without-data-root", _option("experiment=canonical_tosca", "data.root"), _subprocess("lit3d-train"),
     ["missing value for data.root", "set data.root="]),
    ("train-misspelt-key", _option("trainer.max_epoch=3"), train_cli,
     ["Could not override 'trainer.max_epoch'", "did you mean trainer.max_epochs=3?"]),
    # Hydra's own hint for the line above, "+trainer.max_epoch=3": the Trainer refuses it, in one line
    ("train-plus-misspelt-trainer-argument", _option("experiment=completion_demo +trainer.max_epoch=3",
                                                     "trainer.max_epoch"), train_overrides,
     ["not an argument of lightning.pytorch.trainer.trainer.Trainer", "did you mean trainer.max_epochs?"]),
    ("eval-misspelt-key", _option("ckpt_pth=x.ckpt"), eval_cli, ["Could not override 'ckpt_pth'"]),
    ("train-bad-task-option-value", _option("experiment=canonical_demo task.on_nonfinite=bogus", "task config"),
     train_overrides, ["task.on_nonfinite must be one of", "'bogus'"]),
    ("train-misspelt-split", _option("experiment=completion_demo +data.sizes.trian=10", "data.sizes.trian"),
     train_overrides, ["unknown split", "known: train, val, test_same"]),
    ("train-negative-split-size", _option("experiment=completion_demo data.sizes.val=-2", "data.sizes.val=-2"),
     train_overrides, ["expected a whole number of items >= 0"]),
    ("train-zero-epochs", _option("experiment=completion_demo trainer.max_epochs=0", "trainer.max_epochs=0"),
     train_overrides, ["nothing would be trained", "untrained weights"]),
    ("eval-without-ckpt_path", lambda tmp: (None, "ckpt_path"), eval_no_ckpt, ["missing value for ckpt_path"]),
    # checkpoints
    ("eval-ckpt-missing", _missing("nowhere.ckpt"), eval_ckpt, ["checkpoint not found"]),
    ("eval-ckpt-of-another-task", _ckpt("completion"), eval_ckpt, ["checkpoint is for task 'completion', not 'canonical'"]),
    ("eval-ckpt-pickled-object", _ckpt("pickled"), eval_ckpt_any_task,
     ["refused to load pickled Python objects", "Unsupported global", "open"]),
    ("eval-ckpt-garbage", _ckpt("garbage"), eval_ckpt_any_task, ["not a readable checkpoint", "zip archive"]),
    ("eval-ckpt-not-lit3d", _ckpt("foreign"), eval_ckpt_any_task, ["not a lit3d checkpoint"]),
    ("train-resume-pickled-object", _ckpt("pickled"), train_resume, ["refused to load pickled Python objects"]),
    ("train-resume-without-last", lambda tmp: ("last", "last.ckpt"), train_resume, ["no last checkpoint to resume"]),
]

LIBRARY = {mesh_loader, grid_loader, pair_converter, depth_cache, mos_reader}


@pytest.mark.parametrize("write,entry,words", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_gives_one_line(write, entry, words, tmp_path, capsys, monkeypatch, compose_cfg):
    monkeypatch.delenv("HYDRA_FULL_ERROR", raising=False)
    monkeypatch.setenv("LIT3D_CACHE", str(tmp_path / "feature_cache"))
    arg, named = write(tmp_path)
    out = entry(arg, Ctx(tmp_path, capsys, monkeypatch, compose_cfg))
    assert "Traceback" not in out.err, out.err
    if entry in LIBRARY:
        assert isinstance(out.code, str)  # _raises checked the exception type
        lines = out.err.strip().splitlines()
        assert len(lines) == 1, out.err
    else:
        assert isinstance(out.code, int) and out.code != 0, out
        assert out.code == 2, out  # a bad input file / option: exit 2 everywhere
        lines = [ln for ln in out.err.splitlines() if ln.strip()]
        # in-process, stderr holds only our line; a subprocess may also log Lightning INFO lines
        errors = [ln for ln in lines if ln.startswith(("error:", "lit3d-score: error:"))]
        assert len(errors) == 1 and (len(lines) == 1 or "subprocess" in entry.__name__), out.err
        if "subprocess" in entry.__name__:
            assert lines[-1] == errors[0], out.err
    line = lines[-1] if entry not in LIBRARY else lines[0]
    assert line.startswith(("error: ", "lit3d-score: error: ")), line
    assert named in line, (named, line)
    for w in words:
        assert w in line, (w, line)
    assert not (tmp_path / "was_executed").exists(), "a pickled object in a checkpoint was executed"


def test_every_entry_point_is_in_the_table():
    names = {c[2].__name__ for c in CASES}
    for prog in ("score", "lit3d-train", "lit3d-eval", "lit3d-data", "lit3d-train (subprocess)",
                 "lit3d-data (subprocess)", "run_cli(evaluate)", "run_cli(train)"):
        assert prog in names, prog
