"""Make the embedded demo dataset from ../shared/data (run from the repository root).

The VPR-Bench Corridor AMOSNet matrix (111 DB x 111 Q) is split as the paper's protocol
does: the first 10% of the queries (11) form the calibration traverse, with ground
truth; the other 100 are the deployment traverse, whose ground truth is kept apart
(deploy_GT.npy) for evaluation only.
"""

from pathlib import Path

import numpy as np

SRC = Path("..") / "shared" / "data" / "vprbench-corridor"
DST = Path("data") / "corridor"

s = np.load(SRC / "S_AMOSNet.npy")
gt = np.load(SRC / "GT.npy")
n_cal = s.shape[1] // 10
np.save(DST / "cal_S.npy", np.ascontiguousarray(s[:, :n_cal]))
np.save(DST / "cal_GT.npy", np.ascontiguousarray(gt[:, :n_cal]))
np.save(DST / "deploy_S.npy", np.ascontiguousarray(s[:, n_cal:]))
np.save(DST / "deploy_GT.npy", np.ascontiguousarray(gt[:, n_cal:]))
