"""Mesh geometry shared by the tasks: geodesics, MDS/SMACOF/GPS canonical forms, simplification."""
