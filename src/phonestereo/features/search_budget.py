"""The search's budget refilled: windows that fail the NCC tests free their place for the next.

The keypoints are chosen on the left image only, strongest first. Where the right image lost the
texture the left window carries (a one-sided denoiser: a phone's ISP, or a sharper tele), those
windows fail the NCC search and the pair ends with fewer windows to fit than a clean pair of the
same scene. :func:`refill_search` searches the first ``first`` candidates and, while fewer than
``budget`` windows passed the search tests, searches the next candidates (as many as the last
round lost), up to ``limit`` searched in all. The windows of the first round are kept as they
are, so a pair that fills the budget in its first round is matched exactly as without refilling;
refilled windows beyond the budget are not fitted.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields

import numpy as np
from numpy.typing import NDArray

from phonestereo.features.search import SearchResult

Index = NDArray[np.int64]
Mask = NDArray[np.bool_]


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
    top = min(int(limit), int(n_candidates))
    while passed < budget and done < top and lost > 0:
        k = min(lost, top - done)
        parts.append(search(np.arange(done, done + k, dtype=np.int64)))
        ok = passes(parts[-1]).copy()
        ok[np.cumsum(ok) > budget - passed] = False  # not beyond the budget
        oks.append(ok)
        passed += int(ok.sum())
        lost, done = k - int(ok.sum()), done + k
    return np.arange(done, dtype=np.int64), concat_results(parts), np.concatenate(oks)
