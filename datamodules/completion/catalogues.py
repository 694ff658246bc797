"""Real models of the thesis categories from Debian packages (``data.source=installed``).

The bootstrap (``scripts/bootstrap.sh``) downloads the packages with ``apt-get download`` and
unpacks them with ``dpkg-deb -x`` into ``<root>/<package>/`` (root: ``data.root``, else
``$LIT3D_CATALOGUES``, else :data:`DEFAULT_ROOT`); a package installed system-wide (under ``/``)
is used when its unpacked tree is absent. :func:`index_installed` indexes every catalogue present
and names the absent ones. Per package (:data:`CATALOGUES`):

==========================  ==========  ====================================================
package                     licence     models (category rule; format; axes)
==========================  ==========  ====================================================
flightgear-data-ai          GPL-2+      one plane per ``AI/Aircraft/<type>/`` folder (its largest
                                        ``.ac`` outside lights/effects folders); balloons, the
                                        ferry, the hang-glider and the Space Shuttle dropped; y-up, nose -x
crrcsim-data                GPL-2       the ``objects/*.ac`` that a ``models/*.xml`` airplane
                                        names, one per description (scenery, variants, helicopters and
                                        quadcopters dropped); y-up, nose +z
torcs-data                  GPL-2+      car bodies ``.acc``: all dropped (no wheels in the mesh)
ufoai-data                  GPL/CC-BY-SA ``base/0models.pk3``: gun-shaped weapons (firearm), cars
                                        (tyres ``*_t.md2`` / ``*t.md2`` joined), benches, chairs,
                                        couches, tables (:data:`UFOAI_RULES`); z-up; front +y (cars),
                                        +x (the rest)
sweethome3d                 GPL-2+      the default catalogue inside ``sweethome3d.jar``
                                        (Sweet Home 3D's own rules, its size and modelRotation)
minetest-mod-homedecor      CC-BY-SA-4.0 named OBJ models (:data:`HOMEDECOR_RULES`); y-up
sweethome3d-furniture       CC0/CC-BY   the ``*.sh3f`` catalogues of ``data.source=sweethome3d`` (installed by
                                        apt, the demo's data; ids prefixed ``sweethome3d-furniture/``)
==========================  ==========  ====================================================

Every model is returned as a :class:`~datamodules.completion.cad_models.CadModel` in the
project's frame (+y up, front towards +z: its ``rotation``), with its licence and author for
the manifest and ``CREDITS.md``; every model left out is in ``dropped`` with its reason. Model
ids are ``<package>/<name>``, stable across machines, so the split by model id is too.
"""
from __future__ import annotations

import dataclasses
import os
import re
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from datamodules.cache import DataError
from datamodules.completion.cad_models import CadModel
from datamodules.completion.dep5 import read_dep5, stanza_of
from datamodules.completion.sweethome3d import assign_category, index_sweethome3d, parse_properties

DEFAULT_ROOT = "~/.cache/lit3d/catalogues"
ROOT_ENV = "LIT3D_CATALOGUES"


def frame(up: str, forward: str) -> tuple[float, ...]:
    """Row-major 3x3 rotation taking a source frame (``up``, ``forward`` as ``"+x"`` ...) to +y up, +z front."""
    axes = {"x": 0, "y": 1, "z": 2}

    def vec(s: str) -> np.ndarray:
        v = np.zeros(3)
        v[axes[s[1]]] = -1.0 if s[0] == "-" else 1.0
        return v

    u, f = vec(up), vec(forward)
    r = np.stack([np.cross(u, f), u, f])  # rows: new x, y, z in source coordinates
    return tuple(float(x) for x in r.reshape(-1))


def catalogue_root(root: str | Path | None = None) -> Path:
    """Where the unpacked packages are: ``root``, else ``$LIT3D_CATALOGUES``, else :data:`DEFAULT_ROOT`."""
    return Path(os.path.expanduser(str(root or os.environ.get(ROOT_ENV) or DEFAULT_ROOT)))


def package_tree(root: Path, package: str, rel: str) -> Path | None:
    """``<root>/<package>/<rel>`` if unpacked there, else ``/<rel>`` if installed, else None."""
    for base in (root / package, Path("/")):
        if (base / rel).exists():
            return base / rel
    return None


# ---------------------------------------------------------------- FlightGear AI aircraft
FG_REL = "usr/share/games/flightgear/AI/Aircraft"
FG_NOT_PLANES = {"balloon": "hot-air balloons, not planes", "Ferry": "a ferry boat, not a plane",
                 "flash2a": "a hang-glider, not a plane", "SpaceShuttle": "a spacecraft, not a plane"}
FG_PART = re.compile(r"/(lights?|effects)/|light|flare|exhaust|refuel|probe|droptank|tank\.ac|wheels|banner|ssme|omspods",
                     re.IGNORECASE)


def _fg_author(folder: Path) -> str:
    for xml in sorted(folder.rglob("*.xml")):
        m = re.search(r"<author>\s*([^<]+?)\s*</author>", xml.read_text("latin-1"), re.IGNORECASE)
        if m and m.group(1).lower() not in ("me", "unknown"):
            return m.group(1)
    return "FlightGear contributors"


def index_flightgear(tree: Path) -> tuple[list[CadModel], list[dict]]:
    """One plane per aircraft folder (the largest body ``.ac``); other files and non-planes dropped."""
    models, dropped = [], []
    for folder in sorted(p for p in tree.iterdir() if p.is_dir()):
        files = sorted(folder.rglob("*.ac"))
        if folder.name in FG_NOT_PLANES:
            dropped += [{"model": str(f), "reason": FG_NOT_PLANES[folder.name]} for f in files]
            continue
        body = [f for f in files if not FG_PART.search(str(f.relative_to(folder)))]
        if not body:
            dropped += [{"model": str(f), "reason": "no body model in the folder"} for f in files]
            continue
        main = max(body, key=lambda f: (f.stat().st_size, f.name))
        for f in files:
            if f != main:
                why = "a variant or livery (one model per aircraft folder)" if f in body else "a light or part"
                dropped.append({"model": str(f), "reason": f"{why} of {folder.name}"})
        models.append(CadModel(f"flightgear/{folder.name}", "plane", (str(main),), name=folder.name,
                               licence="GPL-2+", creator=_fg_author(folder), rotation=frame("+y", "-x")))
    return models, dropped


# ---------------------------------------------------------------- CRRCSim model planes
CRRC_REL = "usr/share/games/crrcsim"
CRRC_NOT_PLANES = re.compile(r"heli|copter|qc01", re.IGNORECASE)


def index_crrcsim(tree: Path) -> tuple[list[CadModel], list[dict]]:
    """The first ``objects/*.ac`` named by each airplane description ``models/*.xml`` (others: variants
    such as liveries); the ``.ac`` files no description names are scenery."""
    named: dict[str, str] = {}
    for xml in sorted((tree / "models").glob("*.xml")):
        for ac in re.findall(r'model="([^"]+\.ac)"', xml.read_text("latin-1")):
            named.setdefault(ac, xml.stem)
    first = {}
    for ac, xml in named.items():
        first.setdefault(xml, ac)
    models, dropped = [], []
    for f in sorted((tree / "objects").glob("*.ac")):
        if f.name not in named:
            dropped.append({"model": str(f), "reason": "scenery (no airplane description names it)"})
        elif first[named[f.name]] != f.name:
            dropped.append({"model": str(f), "reason": f"a variant of {first[named[f.name]]} "
                            f"(one model per airplane description, {named[f.name]}.xml)"})
        elif CRRC_NOT_PLANES.search(f.name):
            dropped.append({"model": str(f), "reason": "a helicopter or quadcopter, not a plane"})
        else:
            models.append(CadModel(f"crrcsim/{f.stem}", "plane", (str(f),), name=f"{named[f.name]} ({f.stem})",
                                   licence="GPL-2", creator="CRRCSim contributors", rotation=None))  # +y up, nose +z
    return models, dropped


# ---------------------------------------------------------------- TORCS cars
TORCS_REL = "usr/share/games/torcs/cars"


def index_torcs(tree: Path) -> tuple[list[CadModel], list[dict]]:
    """TORCS car bodies: listed, all dropped (the game draws the wheels; not fitted here)."""
    dropped = [{"model": str(d / f"{d.name}.acc"), "reason": "car body without wheels (TORCS draws them from "
                "the car XML); wheel fitting not implemented"} for d in sorted(tree.iterdir()) if d.is_dir()]
    return [], dropped


# ---------------------------------------------------------------- UFO:AI
UFOAI_REL = "usr/share/games/ufoai/base/0models.pk3"
UFOAI_COPYRIGHT = "usr/share/doc/ufoai-data/copyright"  # DEP-5: each model file's licence
UFOAI_GUNS = ("assault bolterrifle chaingun coilgun electrolaser flamer grenl laserheavy laserpistol laserrifle "
              "machinegun needlergun needlerheavy pbeamcannon pbeampistol pbeamrifle pistol pistol2 plasblaster "
              "plaspistol plasrifle rpg2 shotgun shotgun2 shotgunmicro smg sniper vhs xaw95").split()
# (category, member path pattern) over models/...; first match wins; tyre files are joined to their body
UFOAI_RULES: tuple[tuple[str, str], ...] = (
    ("firearm", r"^weapons/(" + "|".join(UFOAI_GUNS) + r")/(?!.*(clip|ammo|rocket))[^/]+\.md2$"),
    ("car", r"^objects/cars/(?!carcrashed|trailer)[^/]+/(?!roof)[^/]+\.md2$"),
    ("couch", r"^objects/furniture/chairs/(bank1|stleer)\.md2$"),
    ("bench", r"^objects/(city/(bench|parkbench)/[^/]+|furniture/chairs/bench)\.md2$"),
    ("chair", r"^objects/furniture/chairs/chair\d*\.md2$"),
    ("table", r"^objects/(city/parktable/parktable|furniture/(comptable/comptable|desk/desk))\.md2$"),
)
UFOAI_TYRES = re.compile(r"(_t|t)\.md2$")


def ufoai_licence(stanzas: list, parts: list[str]) -> tuple[str, str]:
    """(licence, creator) of a UFO:AI model's files (``models/...`` in the archive = ``base/models/...`` in
    ufoai-data's DEP-5 copyright): each file's own licence (``; ``-joined when body and tyres differ) and
    its stanza's group of authors; without the copyright file, the package's two licences."""
    found = [stanza_of(stanzas, f"base/{p}") for p in parts] if stanzas else []
    if not found or any(s is None for s in found):
        return "GPL-2+ or CC-BY-SA-3.0 (per file: ufoai-data's copyright)", "UFO:AI team"
    licences = "; ".join(dict.fromkeys(s.licence for s in found))
    authors = list(dict.fromkeys(a for s in found for a in s.copyright))
    group = ", ".join(authors[:3]) + (f" and {len(authors) - 3} more" if len(authors) > 3 else "")
    return licences, f"UFO:AI team and contributors (this licence's group in ufoai-data's copyright: {group})"


def index_ufoai(pk3: Path) -> tuple[list[CadModel], list[dict]]:
    """Weapons, cars and furniture of UFO:AI's model archive by :data:`UFOAI_RULES` (z-up, front +x)."""
    try:
        with zipfile.ZipFile(pk3) as z:
            members = sorted(n for n in z.namelist() if n.startswith("models/") and n.endswith(".md2"))
    except (OSError, zipfile.BadZipFile) as exc:
        raise DataError(f"{pk3}: not a zip archive ({type(exc).__name__}: {exc})") from exc
    root = Path(str(pk3)[:-len(UFOAI_REL)]) if str(pk3).endswith(UFOAI_REL) else pk3.parent
    stanzas = read_dep5(root / UFOAI_COPYRIGHT)
    models, dropped, stems = [], [], set(members)
    for n in members:
        rel = n[len("models/"):]
        if rel.startswith(("weapons/", "objects/cars/", "objects/furniture/", "objects/city/")):
            body = UFOAI_TYRES.sub(".md2", n)
            if body != n and body in stems and rel.startswith("objects/cars/"):
                continue  # a tyre file: joined to its body below
            category = next((c for c, pat in UFOAI_RULES if re.search(pat, rel)), None)
            if category is None:
                dropped.append({"model": f"{pk3}::{n}", "reason": "not one of the ten categories by UFOAI_RULES "
                                "(ammunition, grenade, blade, equipment, wreck or other object)"})
                continue
            parts = [n] + [t for t in (n[:-4] + "_t.md2", n[:-4] + "t.md2") if t in stems]
            forward = "+y" if category == "car" else "+x"  # seen in renders: cars along y, guns and chairs along x
            licence, creator = ufoai_licence(stanzas, parts)
            models.append(CadModel(f"ufoai/{rel[:-4]}", category, tuple(f"{pk3}::{p}" for p in parts),
                                   name=rel[:-4], licence=licence, creator=creator,
                                   rotation=frame("+z", forward)))
    return models, dropped


# ---------------------------------------------------------------- Sweet Home 3D's default catalogue
SH3D_REL = "usr/share/sweethome3d/sweethome3d.jar"
SH3D_PROPS = "com/eteks/sweethome3d/io/DefaultFurnitureCatalog.properties"
SH3D_NOT = {"TV unit": "a TV cabinet, not a monitor"}  # names the shared RULES would take


def index_sh3d_default(jar: Path) -> tuple[list[CadModel], list[dict]]:
    """The default catalogue in ``sweethome3d.jar`` by Sweet Home 3D's category rules (OBJ, y-up)."""
    try:
        with zipfile.ZipFile(jar) as z:
            _, entries = parse_properties(z.read(SH3D_PROPS).decode("latin-1"))
            members = set(z.namelist())
    except (OSError, KeyError, zipfile.BadZipFile) as exc:
        raise DataError(f"{jar}: no default furniture catalogue ({type(exc).__name__}: {exc})") from exc
    models, dropped = [], []
    for n, e in sorted(entries.items()):
        name, member = e.get("name", f"#{n}"), e.get("model", "").lstrip("/")
        category, reason = assign_category(name, e.get("tags", ""), e.get("category", ""))
        if name in SH3D_NOT:
            category, reason = None, SH3D_NOT[name]
        if category is None or member not in members or not member.endswith(".obj"):
            dropped.append({"model": f"{jar}::{member}", "name": name, "reason": reason if category is None
                            else "model file missing or not OBJ"})
            continue
        rotation = tuple(float(x) for x in e["modelRotation"].split()) if e.get("modelRotation") else None
        try:
            size = tuple(float(e[k]) for k in ("width", "height", "depth"))
        except (KeyError, ValueError):
            size = None
        models.append(CadModel(f"sweethome3d/{Path(member).stem}", category, (f"{jar}::{member}",), name=name,
                               licence="GPL-2+", creator=e.get("creator", "eTeks"), rotation=rotation, size=size))
    return models, dropped


# ---------------------------------------------------------------- Minetest homedecor
HOMEDECOR_REL = "usr/share/games/minetest/mods/homedecor"
HOMEDECOR_RULES: dict[str, str] = {
    "homedecor_bench_large_1": "bench", "homedecor_bench_large_2": "bench",
    "homedecor_office_chair_upscale": "chair", "homedecor_office_chair_basic": "chair",
    "homedecor_deckchair": "chair", "homedecor_kitchen_chair": "chair",
    "homedecor_bathroom_faucet": "faucet", "homedecor_kitchen_faucet": "faucet",
    "plasmascreen_tv": "monitor",
}


def index_homedecor(tree: Path) -> tuple[list[CadModel], list[dict]]:
    """The OBJ models named in :data:`HOMEDECOR_RULES`; the rest (its tables are textured planes) dropped."""
    models, dropped = [], []
    for f in sorted(tree.rglob("*.obj")):
        category = HOMEDECOR_RULES.get(f.stem)
        if category is None:
            why = "a table of textured planes, not a solid" if "table" in f.stem else "not in HOMEDECOR_RULES"
            dropped.append({"model": str(f), "reason": why})
            continue
        models.append(CadModel(f"homedecor/{f.stem}", category, (str(f),), name=f.stem, licence="CC-BY-SA-4.0",
                               creator="Vanessa Ezekowitz (homedecor modpack)", rotation=frame("+y", "-z")))
    return models, dropped


# package -> (path inside the unpacked tree, indexer, download MB)
# ---------------------------------------------------------------- Sweet Home 3D furniture (the demo's data)
SH3F_REL = "usr/share/sweethome3d/furniture"


def index_sh3d_furniture(folder: Path) -> tuple[list[CadModel], list[dict]]:
    """The ``sweethome3d-furniture`` catalogues (``*.sh3f``; ``data.source=sweethome3d`` alone), ids prefixed
    ``sweethome3d-furniture/`` so that they never meet the default catalogue's ``sweethome3d/`` ids."""
    models, dropped = index_sweethome3d(folder)
    return [dataclasses.replace(m, model_id=f"sweethome3d-furniture/{m.model_id}") for m in models], dropped


CATALOGUES: dict[str, tuple[str, Callable[[Path], tuple[list[CadModel], list[dict]]], int]] = {
    "sweethome3d-furniture": (SH3F_REL, index_sh3d_furniture, 120),
    "flightgear-data-ai": (FG_REL, index_flightgear, 287),
    "crrcsim-data": (CRRC_REL, index_crrcsim, 5),
    "torcs-data": (TORCS_REL, index_torcs, 333),
    "ufoai-data": (UFOAI_REL, index_ufoai, 312),
    "sweethome3d": (SH3D_REL, index_sh3d_default, 17),
    "minetest-mod-homedecor": (HOMEDECOR_REL, index_homedecor, 2),
}


def present_packages(root: str | Path | None = None) -> list[str]:
    """The catalogue packages found (unpacked under the catalogue root or installed), in :data:`CATALOGUES` order."""
    base = catalogue_root(root)
    return [p for p, (rel, _, _) in CATALOGUES.items() if package_tree(base, p, rel) is not None]


def index_installed(root: str | Path | None = None, packages: list[str] | None = None
                    ) -> tuple[list[CadModel], list[dict]]:
    """Models of every catalogue present -> (models, dropped); an absent package is one dropped entry.

    Raises:
        DataError: when no catalogue is present at all, saying how to get them.
    """
    base = catalogue_root(root)
    models, dropped = [], []
    for package in packages or list(CATALOGUES):
        if package not in CATALOGUES:
            raise DataError(f"unknown catalogue {package!r}; known: {', '.join(CATALOGUES)}")
        rel, indexer, _ = CATALOGUES[package]
        tree = package_tree(base, package, rel)
        if tree is None:
            dropped.append({"model": package, "reason": f"package not unpacked in {base} nor installed"})
            continue
        ms, ds = indexer(tree)
        models += ms
        dropped += ds
    if not models:
        raise DataError(f"{base}: no catalogue models; run scripts/bootstrap.sh (it unpacks {', '.join(CATALOGUES)} "
                        f"there) or set data.root / ${ROOT_ENV}")
    return models, dropped
