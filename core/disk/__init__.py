"""Conformal flattening of one disk: BFF-style boundary scale factors (``flatten``, ``DiskSystem``),
the L-inf ``uniform`` boundary optimiser, LSCM, and the paper's midedge construction."""
