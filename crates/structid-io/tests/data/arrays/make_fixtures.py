"""Writes the MAT-file and NumPy fixtures of tests/array_files.rs (run from this folder).

Needs numpy and scipy; the tests only read the files written here.
"""
import numpy as np
import scipy.io
import scipy.sparse

k = np.arange(8, dtype=float)
u = np.sin(0.7 * k)
y = 0.5 * u ** 2 - 0.25
variables = {
    "vir": u.reshape(1, -1),  # a row vector
    "qm": y.reshape(-1, 1),  # a column vector
    "data": np.column_stack([u, y]),  # 8x2: samples x channels
    "counts": (k * 3 - 7).astype(np.int16).reshape(-1, 1),
    "gain": np.float32(k / 4).reshape(-1, 1),
    "valid": (k > 2).reshape(-1, 1),
    "title": "record 1",
    "meta": {"fs": 10.0},
    "pieces": np.array([[1.0], "x"], dtype=object),
    "spectrum": (u + 1j * y).reshape(-1, 1),
    "sparse": scipy.sparse.csc_matrix(np.eye(3)),
    "cube": np.zeros((2, 2, 2)),
}
scipy.io.savemat("signals_v5.mat", variables, do_compression=False)
scipy.io.savemat("signals_v7.mat", variables, do_compression=True)

np.save("signals.npy", np.column_stack([u, y]))
np.save("signals_fortran_f4.npy", np.asfortranarray(np.column_stack([u, y]).astype(">f4")))
rec = np.zeros(8, dtype=[("u", "<f8"), ("y", "<f8"), ("n", "<i4")])
rec["u"], rec["y"], rec["n"] = u, y, k.astype(int)
np.save("signals_structured.npy", rec)
np.save("complex.npy", u + 1j * y)
np.savez("signals.npz", vir=u, qm=y, data=np.column_stack([u, y]))
np.savez_compressed("signals_compressed.npz", vir=u, qm=y, data=np.column_stack([u, y]))
np.savetxt("signals.csv", np.column_stack([u, y]), delimiter=",", header="u,y", comments="", fmt="%.17g")
