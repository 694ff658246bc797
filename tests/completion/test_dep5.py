"""Per-file licences from a DEP-5 copyright file (datamodules.completion.dep5) and UFO:AI's models
credited by them (datamodules.completion.catalogues.ufoai_licence)."""
from pathlib import Path

from datamodules.completion.catalogues import ufoai_licence
from datamodules.completion.dep5 import parse_dep5, read_dep5, stanza_of

TEXT = """Format: https://www.debian.org/doc/packaging-manuals/copyright-format/1.0/
Upstream-Name: Example

Files: *
Copyright: 2002-2014, The Team
License: GPL-2+

Files:
 base/models/weapons/a.md2
 base/models/cars/*.md2 base/models/cars/tyre_t.md2
Copyright:
 Ann Author
 Bob Builder
License: CC-BY-SA-3.0

Files: base/models/cars/old.md2
Copyright: Carl
License: GPL-2

License: GPL-2
 The full text of the licence.
 .
 More text.
"""


def test_the_last_matching_stanza_decides_and_continuation_lines_are_read():
    stanzas = parse_dep5(TEXT)
    assert [s.licence for s in stanzas] == ["GPL-2+", "CC-BY-SA-3.0", "GPL-2"]  # stand-alone licence text skipped
    assert stanzas[1].files == ("base/models/weapons/a.md2", "base/models/cars/*.md2", "base/models/cars/tyre_t.md2")
    assert stanzas[1].copyright == ("Ann Author", "Bob Builder")
    assert stanza_of(stanzas, "base/models/weapons/a.md2").licence == "CC-BY-SA-3.0"  # exact path
    assert stanza_of(stanzas, "base/models/cars/new.md2").licence == "CC-BY-SA-3.0"  # glob
    assert stanza_of(stanzas, "base/models/cars/old.md2").licence == "GPL-2"  # a later stanza wins
    assert stanza_of(stanzas, "base/maps/x.bsp").licence == "GPL-2+"  # the package default
    assert stanza_of(parse_dep5(TEXT.replace("Files: *", "Files: base/other/*")), "base/maps/x.bsp") is None


def test_ufoai_models_get_their_own_files_licence(tmp_path):
    stanzas = parse_dep5(TEXT)
    licence, creator = ufoai_licence(stanzas, ["models/cars/old.md2", "models/cars/tyre_t.md2"])
    assert licence == "GPL-2; CC-BY-SA-3.0"  # body and tyres under different licences: both named
    assert "Carl" in creator and "Ann Author" in creator
    assert ufoai_licence([], ["models/weapons/a.md2"])[0].startswith("GPL-2+ or CC-BY-SA-3.0")  # no copyright file
    assert read_dep5(tmp_path / "missing") == [] and read_dep5(Path(__file__)) == []  # absent or not DEP-5

