"""fourws_common: what every fourws package shares.

Importing it (every fourws package's ``__init__`` does, first) sets the default number of
BLAS threads to one, before numpy loads OpenBLAS. fourws works on small matrices only (the
MPC's ≤ 31-variable QPs, 8×8 matrix exponentials), where BLAS threads gain nothing and, on a
loaded machine, spin against the other processes: with the default threads the MPC step
took 12 ms median (9.4 ms of it in ``scipy.linalg.expm``) on two cores busy with a sweep,
against 0.96 ms with one thread (bench/bench_mpc.py, Np 30). A value the user has set is
kept.
"""

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
