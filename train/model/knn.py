"""The kNN graph of the cGNN's edge convolutions: each point's k nearest points, the same
whatever the order of the points.

A regular grid is full of ties: two neighbours at the same distance, exactly or up to rounding
that depends on where a row sits in the matrix. Ranked by index or by the rounding, the
chosen neighbours (and so the answer) would change with the order of the points. Here a tie
is broken by the points themselves: candidates come from one matrix product and ``topk``
(as DGCNN's kNN), their distances are recomputed directly, and :func:`choose` ranks them by
distance with a relative tolerance ``TIE``, a tie going to the smaller :func:`tiebreak` key
(a number made of the point's 3-D coordinates). Only the rows where a tie can change the k
nearest or their order are ranked pairwise (:func:`ordered`); a row whose tie crosses the
k-th neighbour is searched again with more candidates (:func:`nearest`). A traced graph (the
ONNX export) cannot branch: it ranks every row with k + ``EXTRA`` candidates at once.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

BLOCK = 1 << 20     # distances per piece of the kNN on a CPU: 4 MB, which stays in cache
EXTRA = 2           # candidates beyond k in a traced graph, which cannot search again
WIDEST = 64         # the most candidates a row with a wide tie is searched again with
TIE = 1e-5          # relative difference of two distances taken as a tie
FAR = 1e30          # the distance of a candidate that may not be chosen
WEIGHTS = (1.0, 2.0 ** 0.5, 3.0 ** 0.5)   # of x, y, z in a point's tie-breaking key


def knn(features: torch.Tensor, k: int, mask: torch.Tensor | None = None,
        key: torch.Tensor | None = None) -> torch.Tensor:
    """Indices (B, N, k) of each point's k nearest points by feature distance, itself included,
    nearest first: the same neighbours whatever the order of the points.

    ``mask`` (B, N) bool: points that may be neighbours (False for a missing marker; its
    features must still be finite, as the data's zero-filled points are: inf - inf is NaN).
    ``key`` (B, N): what breaks a tie, one number per point from its 3-D coordinates
    (:func:`tiebreak`; by default of the first three features).

    The k + 1 candidates come from squared distances up to a per-row constant,
    ``|x_j|^2 - 2 x_i.x_j`` (``|x_i|^2`` does not change a row's order), with a masked point's
    ``|x_j|^2`` set to infinity: one matrix product and no pass to mask it. Their distances
    are then recomputed directly and ranked by :func:`choose`, so that a tie (a regular grid)
    is broken by the points themselves, not by their index or by rounding that depends on a
    row's position. On a CPU the (B, N, N) matrix is made and searched in pieces of ``BLOCK``
    distances (whole samples, or rows of one): memory linear in N, and each piece is searched
    while it is in cache. A traced graph (the ONNX export, N dynamic) and a GPU take one
    matrix.
    """
    with torch.no_grad():                     # the graph is chosen, not differentiated
        x = features.detach()
        key = tiebreak(x[..., :3]) if key is None else key.detach()
        sq = (x * x).sum(-1)                                               # (B, N)
        if mask is not None:
            sq = sq.masked_fill(~mask, float("inf"))
        b, n, _ = x.shape
        if torch.jit.is_tracing() or x.device.type != "cpu" or b * n * n <= BLOCK:
            return nearest(x, x, sq, k, key)
        out = torch.empty(b, n, k, dtype=torch.long)
        samples, rows = max(1, BLOCK // (n * n)), max(1, BLOCK // n)
        for s in range(0, b, samples):
            one = slice(s, s + samples)
            for r in range(0, n, rows):
                out[one, r:r + rows] = nearest(x[one, r:r + rows], x[one], sq[one], k,
                                               key[one])
        return out


def nearest(queries: torch.Tensor, x: torch.Tensor, sq: torch.Tensor, k: int,
            key: torch.Tensor) -> torch.Tensor:
    """Indices (B, Q, k) of the k points of ``x`` (B, N, F) nearest each query (B, Q, F),
    given ``sq`` (B, N): each point's squared norm (infinite where it may not be chosen), and
    ``key`` (B, N), the tie-breaker.

    A row whose farthest candidate ties with its k-th neighbour (a tie across the k-th: a
    grid's edge, a point at the centre of a ring) is searched again with four times the
    candidates, up to ``WIDEST``; a traced graph cannot branch, so it takes k + ``EXTRA``
    (enough for a regular grid's ties) at once.
    """
    b, n, _ = x.shape
    flat = Points(x.reshape(b * n, -1), key.reshape(b * n), n)
    base = (torch.arange(b, device=x.device) * n).view(b, 1, 1)
    if fixed_width():   # no branch (and in a trace N unknown): k + EXTRA points that are
        pad = x.new_zeros(b, k + EXTRA, x.shape[-1])   # never chosen, so topk has enough
        d = torch.baddbmm(torch.cat([sq, torch.full_like(pad[..., 0], float("inf"))], 1)
                          .unsqueeze(1), queries, torch.cat([x, pad], 1).transpose(1, 2),
                          alpha=-2.0)                                  # (B, Q, N + k + EXTRA)
        return ranked(*candidates(d, k + EXTRA), queries, flat, base, k)[0]
    d = torch.baddbmm(sq.unsqueeze(1), queries, x.transpose(1, 2), alpha=-2.0)   # (B, Q, N)
    want = min(k + 1, n)
    idx, wide = ranked(*candidates(d, want), queries, flat, base, k)
    while want < min(n, WIDEST) and bool(wide.any()):
        want = min(4 * want, n, WIDEST)
        bi, qi = wide.nonzero(as_tuple=True)
        rows = d[bi, qi].unsqueeze(1)                                      # (R, 1, N)
        more, still = ranked(*candidates(rows, want), queries[bi, qi].unsqueeze(1), flat,
                             (bi * n).view(-1, 1, 1), k)
        idx[bi, qi], wide = more[:, 0], torch.zeros_like(wide)
        wide[bi, qi] = still[:, 0]
    return idx


@dataclass
class Points:
    """The points a search chooses from, flattened over the batch: features (B N, F), keys
    (B N,) (:func:`tiebreak`), and N (a candidate index past it is padding)."""

    features: torch.Tensor
    key: torch.Tensor
    n: int


def candidates(d: torch.Tensor, c: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The c smallest of each row of ``d`` (B, Q, N), unordered: their indices (B, Q, c) and
    whether each may be chosen (finite)."""
    cand = d.topk(c, dim=-1, largest=False, sorted=False).indices
    return cand, torch.isfinite(d.gather(-1, cand))


def ranked(cand: torch.Tensor, usable: torch.Tensor, queries: torch.Tensor, points: Points,
           base: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The k nearest (B, Q, k) of the candidates ``cand`` (B, Q, c) by their recomputed
    distances (:func:`choose`), and which rows may have left a tied point out (B, Q): their
    farthest candidate ties with their k-th neighbour, and all candidates were usable.

    ``usable`` (B, Q, c): False for a masked or padding candidate; ``base`` (B, 1, 1) or
    (R, 1, 1): each row's first point in ``points``.

    Outside a traced graph, :func:`choose` (c x c comparisons) runs only on the rows where a
    tie can change the k nearest or their order (:func:`apart`: a random cloud's rows are
    almost all apart, a grid's almost none); the others are their distances' order, which is
    what :func:`choose` gives them. A traced graph cannot branch, and on a GPU the branch
    costs more than it saves (each is a wait for the device): they rank every row."""
    rows = (cand.clamp(max=points.n - 1) + base).reshape(-1)
    exact = torch.linalg.vector_norm(points.features.index_select(0, rows).reshape(
        *cand.shape, -1).sub_(queries.unsqueeze(2)), dim=-1)                  # (B, Q, c)
    exact = exact.masked_fill(~usable, FAR)
    if fixed_width() or exact.device.type != "cpu":
        pick = choose(exact, points.key.index_select(0, rows).reshape(cand.shape), k)
    else:
        pick = ordered(exact, rows.view(cand.shape), points.key, k)
    last = exact.gather(-1, pick[..., -1:]).squeeze(-1)
    edge = exact.masked_fill(~usable, -1.0).amax(-1)
    return cand.gather(-1, pick), (edge - last <= TIE * edge) & usable.all(-1)


def ordered(exact: torch.Tensor, rows: torch.Tensor, key: torch.Tensor, k: int
            ) -> torch.Tensor:
    """:func:`choose`'s positions (..., k) of the k nearest of c candidates, from their
    distances (..., c), their points (..., c) in ``key`` (the flat keys, :func:`tiebreak`):
    the sorted order where the k + 1 nearest are :func:`apart`, :func:`choose` elsewhere."""
    dist, order = exact.sort(-1)                                           # (..., c)
    tied = ~apart(dist[..., :k + 1])                                       # (...,)
    if bool(tied.all()):                                     # a grid: no row to spare
        return choose(exact, key[rows], k)
    pick = order[..., :k].clone()
    if bool(tied.any()):
        at = tied.nonzero(as_tuple=True)
        pick[at] = choose(exact[at], key[rows[at]], k)
    return pick


def fixed_width() -> bool:
    """Whether the search must not branch on the data: a traced graph (the ONNX export) or a
    CUDA graph being captured (a branch would read the device mid-capture)."""
    return torch.jit.is_tracing() or (torch.cuda.is_available()
                                      and torch.cuda.is_current_stream_capturing())


def apart(dist: torch.Tensor) -> torch.Tensor:
    """Whether each row of sorted distances (..., m) has every two neighbours apart by more
    than twice ``TIE`` (relative) (...,): then :func:`choose` ranks them in this order
    whatever their keys (the margin covers float rounding of its tolerance)."""
    nxt = dist[..., 1:]
    return (nxt - dist[..., :-1] > 2 * TIE * nxt).all(-1)


def tiebreak(points: torch.Tensor) -> torch.Tensor:
    """Each point's tie-breaking key (...,) from its coordinates (..., 3),
    ``x + sqrt(2) y + sqrt(3) z``: elementwise, so a point's key does not depend on where it
    is in the array, and two points of a grid never share it (two that do are the same
    point, with the same features)."""
    x, y, z = points.unbind(-1)
    return x * WEIGHTS[0] + y * WEIGHTS[1] + z * WEIGHTS[2]


def choose(dist: torch.Tensor, key: torch.Tensor, k: int) -> torch.Tensor:
    """Positions (..., k) of the k nearest of c candidates, nearest first, from their
    distances (..., c) and keys (..., c) (:func:`tiebreak`).

    Candidate b comes before a when it is nearer by more than ``TIE`` (relative), or when the
    two tie within it and b's key is smaller. A candidate's rank is the number that come
    before it: it depends on the candidates' values only, never on their positions, and two
    distances equal in exact arithmetic tie whatever their rounding.
    """
    da, db = dist.unsqueeze(-1), dist.unsqueeze(-2)                        # (..., c, c)
    tol = TIE * torch.maximum(da, db)
    before = (db < da - tol) | (((da - db).abs() <= tol) & (key.unsqueeze(-2) <
                                                            key.unsqueeze(-1)))
    rank = before.sum(-1).to(dist.dtype)                                   # (..., c)
    return rank.topk(k, dim=-1, largest=False, sorted=True).indices
