"""Type stubs of the compiled module; the docstrings are on the compiled objects."""

import os
from typing import Literal, TypedDict, final

import numpy as np
from numpy.typing import ArrayLike, NDArray

__version__: str

_Matching = Literal["single", "multi"]
# A matrix argument: an array, or the path of a .npy file (ground truth: .npy or a
# VPR_Tutorial .npz with GThard and optional GTsoft), read by the same reader as the CLI.
_Matrix = ArrayLike | str | os.PathLike[str]

class _Counts(TypedDict):
    tp: int
    fp: int
    positives: int
    precision: float
    recall: float

@final
class TransferResult:
    @property
    def thresholds(self) -> NDArray[np.float64]: ...
    @property
    def quantiles(self) -> NDArray[np.float64]: ...
    @property
    def segments(self) -> list[tuple[int, int]]: ...
    @property
    def query_quantiles(self) -> NDArray[np.float64]: ...
    @property
    def query_thresholds(self) -> NDArray[np.float64]: ...
    @property
    def query_weights(self) -> NDArray[np.float64]: ...
    @property
    def neighbours(self) -> NDArray[np.int64]: ...

@final
class Calibration:
    def __init__(
        self,
        s_cal: _Matrix,
        gt_cal: _Matrix,
        *,
        gt_soft: _Matrix | None = None,
        matching: _Matching = "single",
        query_major: bool = False,
    ) -> None: ...
    def transfer(
        self,
        s_val: _Matrix,
        *,
        k: int = 10,
        precision: float = 1.0,
        segment_size: int | None = None,
        query_major: bool = False,
    ) -> TransferResult: ...
    def threshold(self, precision: float = 1.0) -> float: ...
    def __len__(self) -> int: ...
    @property
    def matching(self) -> _Matching: ...

def quantile_transfer(
    s_cal: _Matrix,
    gt_cal: _Matrix,
    s_val: _Matrix,
    *,
    gt_soft: _Matrix | None = None,
    k: int = 10,
    precision: float = 1.0,
    matching: _Matching = "single",
    segment_size: int | None = None,
    query_major: bool = False,
) -> TransferResult: ...
def best_threshold(
    s: _Matrix,
    gt: _Matrix,
    *,
    gt_soft: _Matrix | None = None,
    precision: float = 1.0,
    matching: _Matching = "single",
    query_major: bool = False,
) -> float: ...
def counts(
    s: _Matrix,
    gt: _Matrix,
    threshold: float,
    *,
    gt_soft: _Matrix | None = None,
    matching: _Matching = "single",
    query_major: bool = False,
) -> _Counts: ...
def ranked_correlation(
    s_val: _Matrix,
    s_cal: _Matrix,
    *,
    query_major: bool = False,
) -> NDArray[np.float64]: ...
