"""The search's budget refilled: windows that fail the NCC tests free their place for the next.

The keypoints are chosen on the left image only (the strongest |DoG| of each 8 × 8 cell first,
``MatchConfig.max_keypoints`` of them). Where the right image cannot match many of them (a
phone's ISP: the real phone pairs pass 14–32 % of their first 2000 windows, against 47–58 % on
the clean Middlebury pairs), the pair ends with fewer windows to fit than its texture allows.
:func:`refill_search` searches the first ``max_keypoints`` candidates and, while fewer than
:data:`REFILL_BUDGET` × ``max_keypoints`` windows passed the search tests, searches the next
candidates (as many as the last round lost), up to :data:`REFILL_LIMIT` × ``max_keypoints``
searched in all. The first round's windows are all kept, so a pair that fills the budget in its
first round is matched exactly as without refilling; refilled windows beyond the budget are not
fitted.

The candidates come from one detection of :data:`REFILL_LIMIT` × ``max_keypoints`` in the
detector's priority order; on an image whose strongest responses cluster in fewer cells than
``max_keypoints`` (the phone pairs), the first round is then spread over more cells than a
detection capped at ``max_keypoints`` would pick (that alone: 97–302 → 181–473 matches per phone
pair; the Middlebury pairs' first rounds are unchanged).

Measured (docs/matching.md "Spending the keypoint budget where a match can exist"):
phone_wide_ultra 97–302 → 233–713 matches per pair (≥ 100 on 15 → 16 of 16), their median |e|
and σ_d unchanged, left→right vs right→left RMS z 0.45–1.00 → 0.65–1.06; Middlebury-Q and the
motorcycle unchanged except Piano (clean 663 → 699 matches, 0.0673 → 0.0671 px; its JPEG and
sharpened cases keep 81–97 % instead of 75–87 %); the one-sided denoiser's ratios are not
helped (Adirondack 47 → 49 %, Piano 60 %: the refilled windows are weak and it spoiled them
first); the flows' application phase unchanged (median CPU 74.1 → 74.2 ms per capture on the
demo set; its 450-keypoint ROIs refill only at the closest distance).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields

import numpy as np
from numpy.typing import NDArray

from phonestereo.features.search import SearchResult

Index = NDArray[np.int64]
Mask = NDArray[np.bool_]

#: Windows that may leave the search, × ``max_keypoints``. 0.5: about what the clean Middlebury
#: pairs pass in their first round (Adirondack 1161, Piano 947, motorcycle 1140 of 2000), so they
#: are matched as before (Piano refills 53); 0.6 lifts the clean pairs too (Adirondack 883 → 907,
#: Piano 663 → 854) and puts Piano's JPEG q70 over its limit (0.1060 px against 0.1026).
REFILL_BUDGET = 0.5
#: Candidates searched at most, × ``max_keypoints`` (the search's cost on a pair whose windows
#: mostly fail: the phone pairs search up to 8000 instead of 2000).
REFILL_LIMIT = 4.0
#: Fewest candidates a refill round searches at once (pure speed: a round is searched in
#: pieces until the budget fills; each piece costs one search call's overhead, ~0.1 ms).
_MIN_PIECE = 64


def concat_results(parts: list[SearchResult]) -> SearchResult:
    """The searches of several keypoint batches as one :class:`SearchResult` (in order)."""
    if len(parts) == 1:
        return parts[0]
    names = [f.name for f in fields(SearchResult)]
    return SearchResult(**{n: np.concatenate([getattr(p, n) for p in parts]) for n in names})


def refill_search(
    search: Callable[[Index], SearchResult],
    passes: Callable[[SearchResult], Mask],
    n_candidates: int,
    *,
    first: int,
    budget: int,
    limit: int,
) -> tuple[Index, SearchResult, Mask]:
    """Search candidates in priority order until ``budget`` pass the tests (or ``limit``).

    Parameters
    ----------
    search : callable
        ``search(indices)`` → the :class:`SearchResult` of those candidates.
    passes : callable
        ``passes(result)`` → which of its windows pass the search tests, shape (n,).
    n_candidates : int
        Candidates available, in priority order.
    first : int
        Candidates searched in the first round.
    budget : int
        Windows that may pass; refills stop once as many passed (the first round's are all
        kept, so a budget ≤ its passes changes nothing).
    limit : int
        Most candidates searched in all rounds.

    Returns
    -------
    searched : ndarray of int, shape (M,)
        Indices of the searched candidates, 0 … M − 1 (a prefix of the priority order).
    result : SearchResult
        Their search, concatenated.
    keep : ndarray of bool, shape (M,)
        Passed the tests and within the budget.

    Examples
    --------
    Candidates 0, 2, 4, … pass; a budget of 4 after a first round of 4 (2 pass, 2 lost)
    searches 2 more (1 passes, 1 lost), then 1 more (passes):

    >>> from phonestereo.features.search import SearchResult
    >>> def search(ix):
    ...     v = ix.astype(float)
    ...     b = np.ones(len(ix), bool)
    ...     return SearchResult(b, v, v, v, v, v, v, ~b, b)
    >>> s, res, keep = refill_search(search, lambda r: r.d0 % 2 == 0, 20, first=4, budget=4,
    ...                              limit=12)
    >>> len(s), np.flatnonzero(keep).tolist()
    (7, [0, 2, 4, 6])
    """
    n1 = min(int(first), int(n_candidates))
    parts = [search(np.arange(n1, dtype=np.int64))]
    oks = [passes(parts[0])]
    passed, lost, done = int(oks[0].sum()), n1 - int(oks[0].sum()), n1
    rate = passed / max(n1, 1)  # the last round's pass rate
    top = min(int(limit), int(n_candidates))
    while passed < budget and done < top and lost > 0:
        k = min(lost, top - done)
        end, gained = done + k, 0
        # The round in pieces sized by the last pass rate: the candidates after the one that
        # fills the budget are not searched (they would not be kept; the kept windows are the
        # same as with the whole round searched, only fewer failures are counted).
        while done < end and passed < budget:
            need = budget - passed
            m = min(end - done, max(_MIN_PIECE, int(np.ceil(1.25 * need / max(rate, 0.02)))))
            parts.append(search(np.arange(done, done + m, dtype=np.int64)))
            ok = passes(parts[-1]).copy()
            ok[np.cumsum(ok) > need] = False  # not beyond the budget
            oks.append(ok)
            passed, gained, done = passed + int(ok.sum()), gained + int(ok.sum()), done + m
        lost, rate = k - gained, gained / k
    return np.arange(done, dtype=np.int64), concat_results(parts), np.concatenate(oks)
