"""Helpers the tests share (the only modules a test imports besides the package; no test imports another
test module)."""
