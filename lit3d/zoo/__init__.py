"""lit3d's model zoo: trained weights that ship inside the package (no download), each with a card.

    lit3d.models()                      # [{"name", "task", "path", "bytes", "card", "trained_on", "command"}, ...]
    lit3d.load("body-regressor")        # a zoo name as well as a checkpoint path

Each entry names its file (package data beside this module, or the quality task's shipped model),
the data it was trained on (only data whose licence allows shipping the weights: Sweet Home 3D and the
Debian catalogues, Anny and procedural shapes, CPCD2 phil), the command that remakes it and its card under
``docs/models/``. The CLIs use these as defaults: ``lit3d-reconstruct --body`` starts from ``body-regressor`` unless
``--body-init none``; ``lit3d-score`` scores coloured point clouds with ``cpcd2-phil-fusion``.
``lit3d-reconstruct IMAGE`` completes with ``completion-furniture`` when no ``--ckpt`` is given, and
``--canonical`` with no path uses ``canonical-people`` (each only where its file is installed).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

from lit3d.utils.errors import Lit3dError

HERE = Path(__file__).resolve().parent


class ZooError(Lit3dError, ValueError):
    """A name that is not in the zoo, or a zoo file missing from this installation."""


@dataclass(frozen=True)
class ZooModel:
    """One trained model of the zoo (see the module doc); ``file`` is relative to ``lit3d/``."""

    name: str
    task: str
    file: str
    trained_on: str
    command: str
    card: str

    @property
    def path(self) -> Path:
        return HERE.parent / self.file

    def describe(self) -> dict:
        path = self.path
        return {**asdict(self), "path": str(path), "bytes": path.stat().st_size if path.is_file() else None}


ZOO: dict[str, ZooModel] = {m.name: m for m in (
    ZooModel("completion-furniture", "completion", "zoo/completion-furniture.pt",
             "data=completion_installed: real furniture of the installed catalogues (Sweet Home 3D, Minetest "
             "homedecor) for bench, chair, couch and table, 120 models in 1,800 views rendered in 3D-RecGAN++'s "
             "geometry (the Debian game catalogues' cars, firearms and planes only in its unseen test split); "
             "30 epochs, seed 42, 66 min on one CPU thread (shared)",
             "OUT=logs/zoo_completion SEED=42 bash studies/zoo/remake_completion_furniture.sh "
             "(lit3d-train experiment=completion_furniture)",
             "docs/models/completion_furniture.md"),
    ZooModel("canonical-people", "canonical", "zoo/canonical-people.pt",
             "Anny people (data=anny): 200 adult phenotypes of Anny's shape distribution, each in 30 poses of its "
             "own, split by subject and pose (140 training subjects, 3,360 pairs); experiment=canonical_people "
             "(12 epochs) then canonical_people_identity (8 epochs with a subject classifier), seed 42, "
             "one CPU thread (shared)",
             "OUT=logs/zoo_people SEED=42 bash studies/zoo/remake_canonical_people.sh "
             "(lit3d-train experiment=canonical_people, then experiment=canonical_people_identity)",
             "docs/models/canonical_people.md"),
    ZooModel("body-regressor", "body", "zoo/body-regressor.pt",
             "Anny people drawn and rendered on the fly (adult shape distribution, the 'upright' pose mix: standing "
             "people in the fit's joint limits, turned up to 15 degrees), seed 7, 12,500 steps in 63 min on one "
             "CPU thread",
             "lit3d-train experiment=body_regressor, then lit3d.zoo.slim.slim_checkpoint of its best checkpoint "
             "(half=False, data_overrides={'faust_root': None})",
             "docs/models/body_regressor.md"),
    ZooModel("cpcd2-phil-fusion", "quality", "quality/models/cpcd2-phil-fusion.json",
             "CPCD2.0 phil (30 coloured point clouds, MOS 1..5)",
             "lit3d-train experiment=quality_cpcd2_fusion data.root=PATH/cpcd2_phil",
             "docs/quality_model.md"),
)}


def models() -> list[dict]:
    """Every zoo model as a dict: name, task, file, path, bytes (None: the file is not installed), trained_on,
    command, card."""
    return [m.describe() for m in ZOO.values()]




def is_zoo_name(value) -> bool:
    """True when ``value`` names a zoo model and no file of that name exists (a file wins over the zoo)."""
    return isinstance(value, str) and value in ZOO and not Path(value).exists()


def resolve(value: str | Path) -> tuple[Path, str]:
    """``(path, label)`` of a checkpoint argument that may be a file or a zoo name: a file that exists wins
    over a zoo entry of the same name; a zoo name gives its installed file (a :class:`ZooError` line when
    the file is not installed). ``label`` says which, for the console ("shipped completion-furniture (PATH)")."""
    if is_zoo_name(value):
        model = zoo_model(value)
        return model.path, f"shipped {model.name} ({model.path})"
    return Path(value), str(Path(value))


def zoo_model(name: str) -> ZooModel:
    """The zoo entry ``name`` whose file is installed; a :class:`ZooError` line otherwise."""
    if name not in ZOO:
        raise ZooError(f"'{name}' is neither a file nor a zoo model (the zoo has: {', '.join(ZOO)})")
    model = ZOO[name]
    if not model.path.is_file():
        raise ZooError(f"zoo model '{name}': its file {model.path} is not in this installation (remake it: "
                       f"{model.command})")
    return model
