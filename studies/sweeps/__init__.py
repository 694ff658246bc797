"""The sweeps' tables by hand: ``collect`` writes a multirun's sweep_results.md again."""
