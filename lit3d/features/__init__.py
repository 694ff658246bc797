"""Rendering-based features of shape pairs (render -> image measures -> named feature table)
and the feature-matrix container the quality task and its data module share."""

# px of the renders that lit3d-score, lit3d.score and lit3d-reconstruct --reference compare when no size is given
# (here, not in .common, so that lit3d-score's --help imports no torch)
SCORE_SIZE = 256
