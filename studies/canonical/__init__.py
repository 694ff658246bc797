"""The canonical-form studies: the pooled protocol by hand (``pooled``), runs over seeds (``over_runs``), the
warp head's losses (``warp_breakdown``), checkpoints on validation people (``validate_checkpoints``),
results.md with the U-Net rows (``report``)."""
