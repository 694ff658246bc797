"""View-based shape retrieval (CM-BOF style) and depth-image back-projection for the canonical task."""
