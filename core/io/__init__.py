"""File formats: OBJ meshes with per-corner UVs, per-vertex value files, CSV travel times."""
