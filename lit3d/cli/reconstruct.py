"""``lit3d-reconstruct DEPTH... [--ckpt CKPT] --out DIR``: depth images -> completed meshes.

Examples::

    lit3d-reconstruct scan.png --out out/          # the shipped completion-furniture model (lit3d.models())
    lit3d-reconstruct scan.png --ckpt logs/demo/train/checkpoints/best-009.ckpt --out out/
    lit3d-reconstruct depth_dir/ --ckpt CKPT --out out/ --fx 570.3 --fy 570.3 --cx 320 --cy 240
    lit3d-reconstruct d.npy --ckpt CKPT --out out/ --far 2.0 --remove-plane --format ply
    lit3d-reconstruct d.png --ckpt CKPT --out out/ --reference chair.obj --quality-ckpt Q.ckpt
    lit3d-reconstruct person.png --canonical --out out/   # the shipped canonical-people model, then completion
    lit3d-reconstruct d.png --ckpt CKPT --out out/ --canonical logs/canonical/.../best.ckpt
    lit3d-reconstruct person.png --body [--body-init REGRESSOR.ckpt|none] --out out/  # Anny body fit

Inputs: 16-bit PNG/TIFF and integer .npy/.npz (depth units x --depth-scale metres, default
millimetres), float .npy/.npz metres, .exr metres; 0 and an integer type's maximum (65535:
a sensor's "no reading") = background. A folder gives all its depth files. Camera: --fov
(one field of view across width and height, in (0, 180) degrees, principal point at the
centre) or --fx --fy --cx --cy in pixels (OpenCV convention); the default is the 3D-RecGAN++
camera (fov 49.124 deg). Per input NAME, DIR gets NAME.obj (camera frame: x right, y down,
z forward, metres), NAME_occupancy.npz (packed bits), NAME.png (labelled picture) and
NAME.json (timings, grid sizes, threshold, checkpoint, units applied, score); where two
inputs share a stem, NAME keeps the extension (a_cow_png, a_cow_npy) and a note says so.
An input's files are written together (temp folder, renamed into place when all exist),
never over an input file. A bad input gets one line naming the file and the problem, the
batch goes on, and the exit status is 2; an unusable --out (a file, read-only, would replace
an input, is an input folder) stops the run with exit 2 before the network is loaded. SIGTERM
or Ctrl-C ends with one line saying which sets were kept (exit 143 or 130); a rerun skips them.

--body needs the Anny body model: pip install 'lit3d[body]'. Docs:
https://github.com/lit3d/lit3d/blob/main/docs/reconstruct.md
"""
from __future__ import annotations

import argparse
import functools
import os
import sys
import time
from pathlib import Path

from lit3d.cli.about import report_error, run_argparse_cli, version_line
from lit3d.cli.reconstruct_setup import (  # noqa: F401  (ZOO_*: re-exported)
    ZOO_CANONICAL, ZOO_COMPLETION, Scorer, camera_source, check_args, intrinsics, mask_for, resolve_models, say)

def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lit3d-reconstruct", description=__doc__.split("\n\n")[0],
                                epilog="\n\n".join(__doc__.split("\n\n")[1:]).replace("``", "'"),
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("depth", nargs="+", help="depth image(s) or folder(s) of them")
    p.add_argument("--ckpt", help="completion checkpoint (lit3d-train task=completion) or zoo name; default: the "
                                  "shipped completion-furniture (lit3d.models()); not with --body")
    p.add_argument("--body", action="store_true", help="fit the Anny body model instead (a person; needs lit3d[body])")
    p.add_argument("--body-init", metavar="CKPT", help="with --body: start regressor (default: zoo's; none: mean body)")
    p.add_argument("--body-refine-poor", metavar="N", type=int, default=0, help="with a regressor: N more steps if poor")
    p.add_argument("--out", required=True, help="output folder")
    cam = p.add_argument_group("camera")
    cam.add_argument("--fov", type=float, default=None, help="field of view in degrees (default 49.124)")
    for k in ("fx", "fy", "cx", "cy"):
        cam.add_argument(f"--{k}", type=float, default=None, help=f"intrinsic {k} in pixels (give all four)")
    cam.add_argument("--depth-scale", type=float, default=0.001,
                     help="metres per unit of integer depth images (default 0.001: millimetres)")
    cut = p.add_argument_group("object")
    cut.add_argument("--mask", help="object mask image (non-zero = object), or a folder of masks named like the "
                                    "depth images (NAME.png/.npy...: the same stem exactly)")
    cut.add_argument("--near", type=float, default=None, help="ignore depth nearer than this (metres)")
    cut.add_argument("--far", type=float, default=None, help="ignore depth farther than this (metres)")
    cut.add_argument("--remove-plane", action="store_true", help="remove the dominant plane (table, floor)")
    cut.add_argument("--largest-cluster", action="store_true",
                     help="keep only the largest depth-connected region")
    p.add_argument("--no-fuse", action="store_true",
                   help="do not add the visible surface voxels to the completed grid (network output only)")
    p.add_argument("--format", choices=("obj", "ply", "glb"), default="obj", help="mesh format (default obj)")
    p.add_argument("--canonical", metavar="CKPT", nargs="?", const=ZOO_CANONICAL,
                   help="complete the canonical pose: a canonical-task checkpoint or zoo name (no value: the "
                        f"shipped {ZOO_CANONICAL})")
    p.add_argument("--reference", metavar="REF", help="reference shape (camera frame) to score the result against")
    p.add_argument("--quality-ckpt", metavar="Q", help="quality model checkpoint for the score (with --reference)")
    p.add_argument("--size", type=int, default=256, help="picture panel size in pixels (default 256)")
    p.add_argument("--no-figure", action="store_true", help="skip the picture")
    p.add_argument("--overwrite", action="store_true",
                   help="redo inputs whose outputs in --out are whole and from the same input and options "
                        "(skipped otherwise)")
    p.add_argument("--device", default="cpu", help="torch device (cpu, cuda, cuda:1 ...)")
    p.add_argument("--debug", action="store_true", help="show full tracebacks")
    p.add_argument("--version", action="version", version=version_line("lit3d-reconstruct"))
    return p


def _one(args, path: Path, name: str, completer, mapper, scorer, protected) -> dict:
    from lit3d.reconstruct.depth_io import read_depth_info
    from lit3d.reconstruct.figure import figure_png
    from lit3d.reconstruct.outputs import mesh_bytes, occupancy_npz, request_key, write_outputs
    from lit3d.reconstruct.pipeline import Options, reconstruct

    t_all = time.perf_counter()
    t0 = time.perf_counter()
    depth, units = read_depth_info(path, args.depth_scale)
    notes = list(completer.notes)
    if units["no_reading_pixels"]:
        notes.append(f"{path}: {units['no_reading_pixels']} pixels at the {units['dtype']} maximum taken as "
                     "'no reading' (background)")
        say(f"note: {notes[-1]}")
    t_read = time.perf_counter() - t0
    h, w = depth.shape
    intr = intrinsics(args, w, h, str(path))
    mask, mask_file = mask_for(args, path, depth.shape)
    opts = Options(mask=mask, near=args.near, far=args.far,
                   remove_plane=args.remove_plane, largest_cluster=args.largest_cluster, fuse_input=not args.no_fuse)
    res = reconstruct(depth, intr, completer, opts, label=str(path), canonical=mapper)
    timings = {"read": t_read, **res.timings}
    files = {f".{args.format}": mesh_bytes(res.mesh, args.format),
             "_occupancy.npz": occupancy_npz(res, completer.threshold)}
    if not args.no_figure:
        t0 = time.perf_counter()
        title = f"{path.name}: {len(res.points)} visible points -> {completer.geometry.target_res}^3 grid, " \
                f"threshold {completer.threshold:.2f}" + (" (canonical pose)" if mapper else "")
        files[".png"] = figure_png(depth, res.keep, res.points, res.mesh, title, args.size)
        timings["figure"] = time.perf_counter() - t0
    summary = {
        "input": str(path), "image_size": [w, h], "intrinsics": intr.as_dict(), "camera": camera_source(args),
        "depth_scale": units["depth_scale_applied"],
        "depth_units": units["units"], "depth_dtype": units["dtype"], "no_reading_pixels": units["no_reading_pixels"],
        "checkpoint": completer.path, "threshold": completer.threshold, "device": args.device,
        "geometry": completer.geometry.as_dict(), "placement": res.placement.as_dict(),
        "grids": {"input": [completer.geometry.input_res] * 3, "output": [completer.geometry.target_res] * 3},
        "fuse_input": opts.fuse_input, "counts": res.info, "mesh_frame": "camera (x right, y down, z forward), metres",
        "notes": notes, "output_name": name, "request": request_key(args, path),
        "mask": None if mask_file is None else str(mask_file),
    }
    if mapper is not None:
        summary["mesh_frame"] += "; canonical pose placed at the posed subject's position and size"
    if scorer is not None:
        t0 = time.perf_counter()
        summary["score"] = scorer.score(res.mesh)
        timings["score"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all
    summary["timings_s"] = timings
    write_outputs(args.out, name, files, summary, protected)
    return summary


def main(argv: list[str] | None = None) -> int:
    return run_argparse_cli("lit3d-reconstruct", _parser(), _run_leaving_no_empty_out, argv)


def _run_leaving_no_empty_out(args) -> int:
    """:func:`_run`; the ``--out`` folders that this run created (``--out`` and any missing parents) and
    left empty (a refused checkpoint, every image failing, a stop before the first set) are removed
    again, so a failed run leaves nothing behind."""
    out = Path(args.out).absolute()
    made = []  # the folders that do not exist yet, --out first
    for folder in (out, *out.parents):
        if os.path.lexists(folder):
            break
        made.append(folder)
    try:
        return _run(args)
    finally:
        for folder in made:
            if not folder.is_dir() or folder.is_symlink():
                break
            try:
                folder.rmdir()  # only an empty folder: an OSError otherwise, and it stays with its parents
            except OSError:
                break


def _report(exc: Exception, prefix: str = "") -> int:
    return report_error("lit3d-reconstruct", exc, prefix)


def _protected(args, inputs: list[Path]) -> list[Path]:
    """Every file the run reads: no output may replace one."""
    out = list(inputs)
    for extra in (args.ckpt, args.canonical, args.reference, args.quality_ckpt, args.body_init):
        if extra and extra != "none":
            out.append(Path(extra))
    if args.mask:
        m = Path(args.mask)
        out += [q for q in m.iterdir() if q.is_file()] if m.is_dir() else [m]
    return out


def _plan_outputs(args, inputs: list[Path]) -> tuple[list[str], list[Path]]:
    """Output names per input and the files no output may replace; checks --out and every
    planned output path before anything expensive runs (raises OutputError, exit 2)."""
    from lit3d.reconstruct.body import planned_files
    from lit3d.utils.io import check_output_dir, check_targets, unique_names

    _check_out_is_no_input_folder(args)
    names, notes = unique_names(inputs)
    for note in notes:
        say(f"note: {note}")
    protected = _protected(args, inputs)
    out = Path(args.out)
    planned = [out / f for n in names for f in planned_files(args, n)]
    check_targets(planned, protected)  # before --out is created: a refused run leaves nothing
    check_output_dir(out)
    return names, protected


def _check_out_is_no_input_folder(args) -> None:
    """--out may not be a folder given as input, itself or through a link: a rerun would read the
    outputs (``NAME.png``, ``NAME_occupancy.npz``) as depth images. A subfolder is fine (a folder
    input is not read recursively). Raises OutputError."""
    from lit3d.utils.io import OutputError

    out = Path(args.out)
    for given in map(Path, args.depth):
        if given.is_dir() and given.resolve() == out.resolve():
            via = f", through the link {out} -> {os.readlink(out)}" if out.is_symlink() else ""
            raise OutputError(f"{out}: --out is the input folder {given}{via}; a rerun would read the outputs as "
                              f"depth images: choose another folder (a subfolder such as {given / 'out'} is fine)")


def _dedupe(inputs: list[Path]) -> list[Path]:
    """One entry per file (a file given twice, or in a folder also given, is reconstructed once)."""
    seen, out = set(), []
    for p in inputs:
        key = p.resolve() if p.exists() else p
        if key in seen:
            say(f"note: {p}: given more than once; reconstructed once")
            continue
        seen.add(key)
        out.append(p)
    return out


def _run(args) -> int:
    from lit3d.reconstruct.depth_io import list_inputs

    check_args(args)
    shipped = resolve_models(args)
    inputs = _dedupe(list_inputs(args.depth))  # a missing folder or file list is answered before the imports
    names, protected = _plan_outputs(args, inputs)
    for line in shipped:  # after the output checks: a refused run says one line
        say(line)
    todo = _to_do(args, inputs, names)
    if not todo:
        say(f"{len(inputs)} of {len(inputs)} image(s) already reconstructed into {args.out} with the same input "
             "and options: nothing to do (--overwrite redoes them)")
        return 0
    from tqdm import tqdm

    from lit3d.reconstruct.body import Body, body_one, start_label, start_regressor
    from lit3d.reconstruct.pipeline import load_completer

    completer = None if args.body else load_completer(args.ckpt, args.device)
    regressor = start_regressor(args.body_init) if args.body else None  # a bad file: one line, exit 2
    body = functools.cache(Body) if args.body else None  # anny loads at the first image that gets to the fit
    for note in [f"start: {start_label(regressor)}"] if args.body else completer.notes:
        say(f"note: {note}")
    mapper = None
    if args.canonical:
        from lit3d.reconstruct.canonical import load_canonical

        mapper = load_canonical(args.canonical, args.device)
    scorer = Scorer(args) if args.reference else None
    failed = 0
    status = 0
    skipped = len(inputs) - len(todo)
    inputs, names = [p for p, _ in todo], [n for _, n in todo]
    bar = tqdm(inputs, desc="reconstruct", unit="image", disable=len(inputs) < 2, file=sys.stderr)
    done, current = [], None
    try:
        for k, (path, name) in enumerate(zip(bar, names), 1):
            current = (k, path, name)
            try:
                if body is not None:
                    s = body_one(args, path, name, body, protected, lambda w, h, lb: intrinsics(args, w, h, lb),
                                 camera_source(args), say, regressor)
                else:
                    s = _one(args, path, name, completer, mapper, scorer, protected)
                done.append(name)
                if len(inputs) < 2 and body is not None:
                    say(f"wrote {Path(args.out) / name}_body{{.{args.format},_canonical.{args.format},"
                         f"_canonical_depth.npy,.png,.json}} ({s['timings_s']['total']:.1f} s)")
                elif len(inputs) < 2:
                    say(f"wrote {Path(args.out) / name}.{{{args.format},png,json}} and "
                         f"{name}_occupancy.npz ({s['timings_s']['total']:.1f} s)")
            except Exception as exc:
                if args.debug:
                    raise
                from lit3d.utils.io import OutputError

                failed += 1
                out_fault = isinstance(exc, OutputError)
                with bar.external_write_mode(file=sys.stderr):
                    code = _report(exc, "" if out_fault or str(path) in str(exc) else f"{path}: ")
                status = max(status, code)
                if out_fault:  # the output folder takes no more files (full, gone read-only): stop here
                    failed = len(inputs) - len(done)
                    break
    except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM (lit3d.cli.about.Stopped): say what is kept
        bar.close()
        raise _stopped(args, exc, len(inputs), done, current, skipped) from None
    if len(inputs) > 1 or skipped:
        say(f"{len(inputs) - failed} of {len(inputs)} images reconstructed into {args.out}"
             + (f"; {failed} failed (see above)" if failed else "")
             + (f"; {skipped} already there skipped (--overwrite redoes them)" if skipped else ""))
    return status


def _stopped(args, exc: KeyboardInterrupt, total: int, done: list[str], current, skipped: int):
    """The :class:`lit3d.cli.about.Stopped` of a batch stopped by SIGTERM or Ctrl-C, its line saying
    what was kept: the finished sets (whole: :func:`lit3d.utils.io.write_file_set` finishes a set
    whose renames had begun, and writes nothing of one still being made) and that a rerun skips them.
    ``current``: ``(1-based position, input, output name)`` of the image being made, or None."""
    from lit3d.cli.about import Stopped
    from lit3d.reconstruct.body import is_finished
    from lit3d.reconstruct.outputs import request_key

    at, busy = "before the first image", ""
    if current is not None:
        k, path, name = current
        at = f"at image {k} of {total}"
        whole = name in done or is_finished(args, name, request_key(args, path))
        if name not in done and whole:
            done = [*done, name]  # stopped during its renames, which were finished
        busy = "" if whole else f"; {path} (in progress) was not written"
    n = len(done)
    kept = f"the {n} finished set{'s' if n != 1 else ''} in {args.out} {'are' if n != 1 else 'is'} whole and kept" \
        if n else f"nothing new was written to {args.out}"
    before = f" ({skipped} more done by an earlier run)" if skipped else ""
    return Stopped(getattr(exc, "signame", "SIGINT"), f"{at}{before}: {kept}{busy}; the same command again does "
                   "the rest (finished sets are skipped)")


def _to_do(args, inputs: list[Path], names: list[str]) -> list[tuple[Path, str]]:
    """Settle the sets an interrupted run left in --out, then the (input, name) pairs whose set is
    not already whole with the same input and options (all of them with --overwrite)."""
    from lit3d.reconstruct.body import is_finished
    from lit3d.reconstruct.outputs import request_key
    from lit3d.utils.io import repair_sets

    for note in repair_sets(args.out):
        say(f"note: {note}")
    if args.overwrite:
        return list(zip(inputs, names))
    return [(p, n) for p, n in zip(inputs, names)
            if not is_finished(args, n, request_key(args, p))]


if __name__ == "__main__":
    sys.exit(main())
