"""Whole meshes to UV atlases: cutting along seams, islands, holes, packing, and ``unwrap``, the single
entry for UV work."""
