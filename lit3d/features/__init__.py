"""Rendering-based features of shape pairs (render -> image measures -> named feature table)
and the feature-matrix container the quality task and its data module share."""
