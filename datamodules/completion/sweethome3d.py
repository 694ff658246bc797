"""Sweet Home 3D furniture catalogues (``.sh3f``) as real CAD models of the thesis categories.

The Debian package ``sweethome3d-furniture`` installs zip catalogues in
:data:`DEFAULT_ROOT`; each holds OBJ models (often several parts, not watertight) and a
``PluginFurnitureCatalog.properties`` with every model's name, category, tags, creator, size
and optional ``modelRotation``. The licence is the catalogue's (its ``license=`` line or
``LICENSE.TXT``: public domain / CC0, or Creative Commons Attribution 3.0), kept per model so
the manifest and ``CREDITS.md`` can credit the authors as CC-BY requires.

Categories come from :data:`RULES`: the first rule whose ``name`` pattern matches the model's
name (or, for ``tags``, its tags) and whose ``exclude`` pattern matches neither the name, the
tags nor the catalogue category assigns it; everything else is listed as dropped with the
reason. Identical OBJ files found in two catalogues are kept once.
"""
from __future__ import annotations

import re
import zipfile
import zlib
from pathlib import Path

from datamodules.cache import DataError
from datamodules.completion.cad_models import CadModel

DEFAULT_ROOT = "/usr/share/sweethome3d/furniture"
APT_PACKAGE = "sweethome3d-furniture"

# (category, name pattern, exclusion pattern over name + tags + catalogue category); order matters
RULES: tuple[tuple[str, str, str], ...] = (
    ("couch", r"\b(sofa|couch|futon|settee|loveseat)\b", r"convertible|\bbed\b"),
    ("bench", r"\bbench\b", r"work ?bench|abdominal|fitness|sport"),
    ("chair", r"\b(chair|armchair|stool|seat)\b|\bpuff\b", r"wheel ?chair|car\b|vehicles|high chair|toilet"),
    ("table", r"\b(table|desk)\b", r"lamp|\bfan\b|tennis bat|football|changing|dressing|lights|doors and windows"),
    ("car", r"\b(car|sedan|beetle|suv|van|chevrolet|peugeot|renault|ford|seat leon)\b",
     r"truck|\bbus\b|carpet|cart\b|card\b|trolley"),
    ("monitor", r"\b(tv|television|monitor|flat tv)\b", r"cabinet|stand|remote|plug|intercom|projector|dvd|antenna|shel"),
    ("faucet", r"\b(faucet|tap)\b", r"shower"),
    ("guitar", r"\bguitar\b", r"^$"),
    ("plane", r"\b(plane|airplane|aeroplane|biplane|aircraft)\b", r"^$"),
    ("firearm", r"\b(gun|rifle|pistol|revolver)\b", r"glue|water"),
)


def catalogue_files(root: str | Path | None) -> list[Path]:
    """The ``.sh3f`` catalogues at ``root`` (a file or a folder; None: :data:`DEFAULT_ROOT`).

    Raises:
        DataError: when there is none, saying how to install them.
    """
    root = Path(root or DEFAULT_ROOT)
    files = [root] if root.is_file() else sorted(root.glob("*.sh3f")) if root.is_dir() else []
    if not files:
        raise DataError(f"{root}: no Sweet Home 3D catalogue (*.sh3f); install them with "
                        f"'apt-get install {APT_PACKAGE}' or set data.root=FOLDER")
    return files


def parse_properties(text: str) -> tuple[dict[str, str], dict[int, dict[str, str]]]:
    """A catalogue's properties -> (catalogue keys, ``{n: {key: value}}`` of its models)."""
    head: dict[str, str] = {}
    items: dict[int, dict[str, str]] = {}
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith(("#", "!")) or "=" not in line:
            continue
        key, value = line.split("=", 1)
        m = re.fullmatch(r"(\w+)#(\d+)", key.strip())
        if m:
            items.setdefault(int(m.group(2)), {})[m.group(1)] = value.strip()
        else:
            head[key.strip()] = value.strip()
    return head, items


def catalogue_licence(z: zipfile.ZipFile, head: dict[str, str]) -> str:
    """The catalogue's licence: its ``license=`` line, else the licence named in LICENSE.TXT."""
    if head.get("license"):
        return head["license"]
    for name in z.namelist():
        if name.upper() == "LICENSE.TXT":
            text = z.read(name).decode("latin-1")
            m = re.search(r"Creative Commons Attribution[^\n:]*", text)
            if m:
                return m.group(0).strip().rstrip(":").strip()
            return text.strip().splitlines()[0] if text.strip() else ""
    return ""


def assign_category(name: str, tags: str, catalogue_category: str) -> tuple[str | None, str]:
    """(category or None, reason) of one catalogue entry by :data:`RULES`."""
    low_name, context = name.lower(), f"{name} {tags} {catalogue_category}".lower()
    for category, pattern, exclude in RULES:
        if re.search(pattern, low_name) and not re.search(exclude, context):
            return category, f"name matches {pattern!r}"
    for category, pattern, exclude in RULES:
        if re.search(pattern, low_name):
            return None, f"excluded from {category} by {exclude!r}"
    return None, "not one of the ten thesis categories"


def index_sweethome3d(root: str | Path | None = None) -> tuple[list[CadModel], list[dict]]:
    """Models of the installed (or given) catalogues -> (models, dropped entries with reasons)."""
    models, dropped, seen = [], [], {}
    for path in catalogue_files(root):
        try:
            z = zipfile.ZipFile(path)
        except (OSError, zipfile.BadZipFile) as exc:
            raise DataError(f"{path}: not a Sweet Home 3D catalogue ({type(exc).__name__}: {exc})") from exc
        with z:
            try:
                text = z.read("PluginFurnitureCatalog.properties").decode("latin-1")
            except KeyError:
                raise DataError(f"{path}: no PluginFurnitureCatalog.properties inside") from None
            head, entries = parse_properties(text)
            licence = catalogue_licence(z, head)
            members = set(z.namelist())
            for n, e in sorted(entries.items()):
                name, member = e.get("name", f"#{n}"), e.get("model", "").lstrip("/")
                category, reason = assign_category(name, e.get("tags", ""), e.get("category", ""))
                where = f"{path.name}::{member}"
                if category is None:
                    dropped.append({"model": where, "name": name, "reason": reason})
                    continue
                if member not in members or not member.lower().endswith(".obj"):
                    dropped.append({"model": where, "name": name, "reason": "model file missing or not OBJ"})
                    continue
                digest = zlib.crc32(z.read(member))
                if digest in seen:
                    dropped.append({"model": where, "name": name, "reason": f"same OBJ as {seen[digest]}"})
                    continue
                seen[digest] = where
                rotation = tuple(float(x) for x in e["modelRotation"].split()) if e.get("modelRotation") else None
                try:
                    size = tuple(float(e[k]) for k in ("width", "height", "depth"))
                except (KeyError, ValueError):
                    size = None
                models.append(CadModel(f"sh3d/{path.stem}/{Path(member).stem}", category, (f"{path}::{member}",),
                                       name=name, licence=licence, creator=e.get("creator", ""),
                                       rotation=rotation, size=size))
    return models, dropped


def credits_markdown(models: list[CadModel]) -> str:
    """CREDITS.md text: every kept model with its author and licence (CC-BY asks for credit)."""
    lines = ["# Credits: real models used as completion data", "",
             "Models from the Sweet Home 3D furniture catalogues and the Debian packages of "
             "datamodules/completion/catalogues.py, by licence.", ""]
    by_licence: dict[str, list[CadModel]] = {}
    for m in models:
        by_licence.setdefault(m.licence or "licence not stated", []).append(m)
    for licence, ms in sorted(by_licence.items()):
        lines += [f"## {licence}", ""]
        lines += [f"- {m.name} ({m.category}) by {m.creator or 'unknown'}: `{m.model_id}`"
                  for m in sorted(ms, key=lambda m: m.model_id)]
        lines.append("")
    return "\n".join(lines)
