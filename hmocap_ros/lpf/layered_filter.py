"""Layered particle filtering (thesis sec. 2.2, alg. 1-5), independent of any body model.

The state is a particle array ``(N, D)`` plus normalised weights ``(N,)``. A
:class:`LayeredFilter` holds the layer schedule of alg. 5. One schedule expresses the annealed
particle filter (APF, alg. 2: every layer over all dimensions, with a growing ``beta``), the
hierarchical filter (HPF: layers over subsets of dimensions that follow a kinematic tree), and
mixtures of the two (table 2.2: a few annealing layers, then one layer per body part).

Weighting functions
    ``weight_fn(particles (N, D), layer_index) -> costs (N,)``, called once per layer with the
    whole particle set. The weight is ``w = exp(-cost)`` (eq. 2.8) and the layer uses
    ``w ** beta = exp(-beta * cost)`` (eq. 2.9). A log-likelihood is passed as its negative.
    ``layer_index`` runs ``0 .. L``; ``L`` is the final weighting ``w_t^L`` of alg. 5. A
    non-finite cost gives weight 0; a layer with no finite cost raises ``ValueError``. The
    function must not modify the particle array it is given.
Kernels
    see :mod:`.kernels`: ``kernel(particles, std, rng) -> particles``; Gaussian by default.

Choices where the thesis is vague (each one also stated where it is implemented):

- Step order: alg. 1 as printed: *update* (weigh), *resample*, *propagate*. So layer ``l``
  weighs the set that layer ``l - 1`` (or, for ``l = 0``, the previous frame's kernel
  ``K_t``) propagated, and its kernel ``K_t^l(Psi_l)`` diffuses the set that layer ``l + 1``
  weighs. The set returned is the next frame's input ``x_{t+1}``, already propagated by
  ``K_t``, as in alg. 5.
- ``beta``: fixed per layer (``Layer.beta``, as the annealing rates of table 2.2) or, when
  ``None``, chosen per layer by bisection so that the particle survival rate
  ``1 / (N sum(pi^2))`` hits ``Layer.survival_rate`` (Deutscher and Reid's alpha, ref. [37]
  of the thesis). Eq. 2.9 bounds beta by 1; that only holds when ``exp(-cost)`` is the
  calibrated likelihood, so the bound is ``Layer.beta_max`` (infinite by default).
- Alg. 3: see :func:`layer_diffusion_stds`. Alg. 4: see :func:`layered_resample`.
- Estimate: the weighted mean ``sum(pi x)`` of the set weighed by the last layer (the
  "sample mean" of sec. 2.4.1).
- Particle counts may differ per layer: ``Layer.n_particles`` is how many particles the layer
  weighs, so the previous layer's resampling draws that many (systematic resampling handles
  any count). The final layer's resampling draws the first layer's count, ready for the next
  frame.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from .kernels import Kernel, clip_to_bounds, gaussian_kernel

WeightFn = Callable[[np.ndarray, int], np.ndarray]


# ----------------------------------------------------------------------------- weights


def annealed_weights(costs: np.ndarray, beta: float) -> np.ndarray:
    """Normalised weights ``pi ~ exp(-beta * cost)`` (eq. 2.8 annealed by eq. 2.9), (N,).

    Costs are shifted by their minimum first (the normalisation cancels the shift) so that
    ``exp`` never underflows for the best particle. Non-finite costs get weight 0.
    """
    c = np.asarray(costs, dtype=np.float64)
    finite = np.isfinite(c)
    if not finite.any():
        raise ValueError("weighting function returned no finite cost")
    w = np.zeros_like(c)
    cf = c[finite]
    w[finite] = np.exp(-beta * (cf - cf.min()))
    return w / w.sum()


def effective_sample_size(weights: np.ndarray) -> float:
    """ESS = 1 / sum(pi^2) of normalised weights (N for uniform weights, 1 for one particle)."""
    return float(1.0 / np.dot(weights, weights))


def survival_rate(weights: np.ndarray) -> float:
    """Particle survival rate ESS / N (Deutscher's alpha): the fraction that resampling keeps."""
    return effective_sample_size(weights) / weights.size


def beta_for_survival_rate(costs: np.ndarray, target: float = 0.5, beta_max: float = np.inf,
                           rtol: float = 1e-3, max_iter: int = 100) -> float:
    """Annealing exponent beta(k) of eq. 2.9 whose weights keep ``target`` of the particles.

    The survival rate ``(sum w)^2 / (N sum w^2)`` with ``w = exp(-beta (c - c_min))`` falls
    monotonically from ``n_finite / N`` at beta = 0 towards ``n_ties / N``, so the root is
    bracketed by repeated quadrupling and then found by bisection on log(beta) until the rate
    is within ``rtol * target``. Special cases: all finite costs equal -> the weights do not
    depend on beta, ``min(1, beta_max)`` is returned; ``target`` unreachable at beta -> 0
    (too few finite costs) -> 0; ``beta_max`` keeps more than ``target`` -> ``beta_max``.
    """
    c = np.asarray(costs, dtype=np.float64)
    n = c.size
    c = c[np.isfinite(c)]
    if c.size == 0:
        raise ValueError("weighting function returned no finite cost")
    c = c - c.min()
    if not c.any():
        return float(min(1.0, beta_max))
    if c.size / n <= target:
        return 0.0

    def rate(beta: float) -> float:
        w = np.exp(-beta * c)
        return float(w.sum() ** 2 / (n * np.dot(w, w)))

    lo, hi = 0.0, 1.0 / float(c.mean())
    for _ in range(max_iter):
        if hi >= beta_max:
            if rate(beta_max) >= target:
                return float(beta_max)
            hi = float(beta_max)
            break
        if rate(hi) <= target:
            break
        lo, hi = hi, 4.0 * hi
    else:
        return hi
    beta = hi
    for _ in range(max_iter):
        beta = np.sqrt(lo * hi) if lo > 0.0 else 0.5 * hi
        r = rate(beta)
        if abs(r - target) <= rtol * target:
            break
        if r > target:
            lo = beta
        else:
            hi = beta
    return float(beta)


# ----------------------------------------------------------------------------- diffusion


def annealing_stds(sigma0: np.ndarray, alphas: float | Sequence[float],
                   n_layers: int) -> np.ndarray:
    """Per-layer Gaussian std of the APF inter-layer kernels, eq. 2.10, (n_layers, D).

    ``Sigma^k = alpha_0 ... alpha_{k-1} Sigma_0`` acts on variances, so the std of layer ``k``
    is ``sqrt(alpha_0 ... alpha_{k-1}) * sigma0``. ``alphas`` is one decay rate for every
    layer or a sequence of at least ``n_layers - 1`` rates.
    """
    sigma0 = np.asarray(sigma0, dtype=np.float64)
    n_rates = max(n_layers - 1, 0)
    a = np.asarray(alphas, dtype=np.float64)
    a = np.full(n_rates, float(a)) if a.ndim == 0 else a[:n_rates]
    if a.size < n_rates:
        raise ValueError(f"need {n_layers - 1} variance decay rates, got {a.size}")
    if np.any((a <= 0.0) | (a > 1.0)):
        raise ValueError("variance decay rates must lie in (0, 1] (eq. 2.10)")
    variance_scale = np.concatenate([[1.0], np.cumprod(a)])[:n_layers]
    return np.sqrt(variance_scale)[:, None] * sigma0[None, :]


def layer_diffusion_stds(layer_dims: Sequence[np.ndarray], sigma0: np.ndarray,
                         nu: float) -> np.ndarray:
    """Per-layer diagonal std of the layered Gaussian kernel ``K^l = N(0, Sigma')``, alg. 3.

    Returns (L, D). For layer ``l`` and dimension ``psi``:

    - ``psi`` in ``Psi_l`` and not in ``Psi_{l-1}`` (alg. 3 line 2): ``sigma_psi``;
    - otherwise, if some earlier layer sampled ``psi``: ``nu^(l - m) sigma_psi`` (line 7);
    - otherwise (never sampled yet): 0 (line 9).

    The printed loop over ``m`` overwrites its result at each ``m``, which leaves ``m``
    undefined; here ``m`` is the latest layer ``<= l`` at which ``psi`` *entered* the schedule
    (line 2 fired: ``psi`` in ``Psi_m``, not in ``Psi_{m-1}``). With every layer over all
    dimensions this gives ``nu^l sigma``, i.e. the APF decay of eq. 2.10 with
    ``alpha_k = nu^2``, so the APF stays the special case of the LPF the thesis says it is;
    a dimension that re-enters after a gap restarts at ``sigma``; dimensions filtered by
    earlier layers keep being re-diffused with a geometrically shrinking std.
    """
    sigma0 = np.asarray(sigma0, dtype=np.float64)
    d = sigma0.size
    out = np.zeros((len(layer_dims), d))
    entered = np.full(d, -1)  # layer at which each dimension last entered, -1: never
    prev = np.zeros(d, dtype=bool)
    for li, dims in enumerate(layer_dims):
        cur = np.zeros(d, dtype=bool)
        cur[dims] = True
        entering = cur & ~prev
        entered[entering] = li
        sampled = entered >= 0
        out[li, sampled] = nu ** (li - entered[sampled]) * sigma0[sampled]
        prev = cur
    return out


def weighted_std(particles: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Per-dimension weighted standard deviation of a weighted particle set, (D,)."""
    mean = weights @ particles
    return np.sqrt(np.maximum(weights @ (particles - mean) ** 2, 0.0))


# ----------------------------------------------------------------------------- resampling


def systematic_resample_indices(weights: np.ndarray, n_out: int,
                                rng: np.random.Generator) -> np.ndarray:
    """Systematic resampling (alg. 4 lines 1-9): indices (n_out,) drawn from normalised weights.

    One uniform start ``u_0 ~ U[0, 1/n_out)`` and the comb ``u_j = u_0 + j / n_out``; index
    ``i`` is the first with ``cdf_i > u_j`` (the printed ``while u_j < cdf_i`` has the
    comparison reversed), found for all ``j`` at once with ``searchsorted``.
    """
    cdf = np.cumsum(weights)
    cdf /= cdf[-1]
    u = (rng.random() + np.arange(n_out)) / n_out
    idx = np.searchsorted(cdf, u, side="right")
    return np.minimum(idx, weights.size - 1)


def layered_resample(particles: np.ndarray, weights: np.ndarray, filtered: np.ndarray,
                     rng: np.random.Generator, n_out: int | None = None) -> np.ndarray:
    """Layered systematic resampling, alg. 4: copy only the filtered dimensions, (n_out, D).

    ``filtered`` is a boolean mask (D,) of the dimensions in ``Psi_0 .. Psi_l``. Output
    particle ``j`` takes those dimensions from the resampled source particle and keeps its
    own values elsewhere, so dimensions that neither dynamics nor observations have touched
    yet keep their diversity (sec. 2.2.4). When ``n_out`` differs from N, "its own" values
    are those of particle ``j mod N``. A mask of all True is plain systematic resampling
    (alg. 1 step 2).
    """
    n = particles.shape[0]
    n_out = n if n_out is None else int(n_out)
    idx = systematic_resample_indices(weights, n_out, rng)
    if filtered.all():
        return particles[idx]
    own = particles[np.arange(n_out) % n] if n_out != n else particles
    return np.where(filtered, particles[idx], own)


# ----------------------------------------------------------------------------- schedule


@dataclass(frozen=True, eq=False)
class Layer:
    """One layer ``l`` of alg. 5: sub-state ``Psi_l``, annealing rule, particles, kernel.

    dims: indices ``Psi_l`` the layer samples (None: all dimensions). Ignored for the final
        layer, whose resampling is plain (alg. 5 line 3).
    beta: fixed annealing exponent beta(l) of eq. 2.9; None: chosen so that ``survival_rate``
        of the particles survive resampling (:func:`beta_for_survival_rate`).
    survival_rate: target survival rate when ``beta`` is None (0.5 after Deutscher).
    beta_max: upper bound of the chosen beta.
    n_particles: how many particles the layer weighs (None: as many as it receives).
    std: explicit kernel std per dimension (D,), replacing alg. 3 (or, for the final layer,
        replacing ``sigma0``); 0 leaves a dimension untouched.
    adaptive_scale: if set, the std of every dimension the layer diffuses becomes
        ``adaptive_scale`` times the weighted std of the particles in that dimension (the
        "adaptive diffusion" of Deutscher, used for the APF of sec. 2.4.2).
    kernel: propagation kernel ``kernel(particles, std, rng)``, :func:`.gaussian_kernel` by
        default. For the final layer this is the inter-frame kernel ``K_t``.
    """

    dims: np.ndarray | None = None
    beta: float | None = None
    survival_rate: float = 0.5
    beta_max: float = np.inf
    n_particles: int | None = None
    std: np.ndarray | None = None
    adaptive_scale: float | None = None
    kernel: Kernel = gaussian_kernel

    def __post_init__(self):
        if self.beta is not None and not self.beta >= 0.0:
            raise ValueError(f"beta must be >= 0, got {self.beta}")
        if not 0.0 < self.survival_rate <= 1.0:
            raise ValueError(f"survival_rate must lie in (0, 1], got {self.survival_rate}")
        if self.n_particles is not None and self.n_particles < 1:
            raise ValueError(f"n_particles must be >= 1, got {self.n_particles}")
        if self.dims is not None:
            object.__setattr__(self, "dims", np.unique(np.asarray(self.dims, dtype=np.intp)))
        if self.std is not None:
            object.__setattr__(self, "std", np.asarray(self.std, dtype=np.float64))


@dataclass(frozen=True, eq=False)
class LayeredFilter:
    """Layer schedule of alg. 5: L inter-layer runs ``(K_t^l(Psi_l), w_t^l)`` and the final
    run ``(K_t, w_t^L)``.

    layers: the L inter-layer runs, in order.
    sigma0: default std per dimension (D,), ``Sigma_0`` of alg. 3 and eq. 2.10; also the std of
        the default inter-frame kernel ``K_t`` (motion from frame to frame).
    nu: variance decay rate of alg. 3.
    final: the last run; its kernel is ``K_t``. ``Layer(std=np.zeros(D))`` returns the
        resampled set without propagation.
    lower, upper: box limits (D,) applied after every kernel (joint limits); None: unbounded.
    stds: (L + 1, D) the kernel std of every run, computed once here (alg. 3 or overrides).
    """

    layers: tuple[Layer, ...]
    sigma0: np.ndarray
    nu: float = 0.5
    final: Layer = field(default_factory=lambda: Layer(beta=1.0))
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None
    stds: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        sigma0 = np.asarray(self.sigma0, dtype=np.float64)
        if sigma0.ndim != 1 or np.any(sigma0 < 0.0):
            raise ValueError("sigma0 must be a (D,) array of non-negative std")
        d = sigma0.size
        object.__setattr__(self, "sigma0", sigma0)
        object.__setattr__(self, "layers", tuple(self.layers))
        if not 0.0 < self.nu <= 1.0:
            raise ValueError(f"nu must lie in (0, 1], got {self.nu}")
        for name in ("lower", "upper"):
            v = getattr(self, name)
            if v is not None:
                v = np.broadcast_to(np.asarray(v, dtype=np.float64), (d,))
                object.__setattr__(self, name, v)
        dims = []
        for li, layer in enumerate(self.layers + (self.final,)):
            if layer.dims is not None and layer.dims.size and \
                    (layer.dims[0] < 0 or layer.dims[-1] >= d):
                raise ValueError(f"layer {li}: dims out of range for D={d}")
            if layer.std is not None and layer.std.shape != (d,):
                raise ValueError(f"layer {li}: std has shape {layer.std.shape}, expected ({d},)")
            dims.append(np.arange(d) if layer.dims is None else layer.dims)
        stds = np.empty((len(self.layers) + 1, d))
        stds[:-1] = layer_diffusion_stds(dims[:-1], sigma0, self.nu)
        stds[-1] = sigma0
        for li, layer in enumerate(self.layers + (self.final,)):
            if layer.std is not None:
                stds[li] = layer.std
        object.__setattr__(self, "stds", stds)

    @property
    def n_dims(self) -> int:
        return self.sigma0.size

    @property
    def n_layers(self) -> int:
        """Number of weightings per run, L + 1 (the final run included)."""
        return len(self.layers) + 1


@dataclass(frozen=True, eq=False)
class LayerDiagnostics:
    """What one layer did: ESS and survival rate of its weights, beta, cost, time."""

    layer: int
    n_evaluations: int
    beta: float
    ess: float
    survival_rate: float
    min_cost: float
    estimate: np.ndarray
    weight_time_s: float
    filter_time_s: float


@dataclass(frozen=True, eq=False)
class LayeredRunResult:
    """Output of :func:`lpf_run`.

    estimate: (D,) weighted mean (or best particle) of the set weighed by ``w_t^L``.
    particles: (N, D) the next frame's unweighted set ``x_{t+1}`` (propagated by ``K_t``).
    weighted_particles, weights: the set weighed by ``w_t^L`` and its normalised weights.
    layers: per-layer diagnostics, L + 1 entries.
    """

    estimate: np.ndarray
    particles: np.ndarray
    weighted_particles: np.ndarray
    weights: np.ndarray
    layers: tuple[LayerDiagnostics, ...]

    @property
    def n_evaluations(self) -> int:
        return sum(d.n_evaluations for d in self.layers)


# ----------------------------------------------------------------------------- runs


def gpf_run(particles: np.ndarray, weight_fn: WeightFn, std: np.ndarray, rng: np.random.Generator,
            layer: Layer = Layer(beta=1.0), layer_index: int = 0,
            filtered: np.ndarray | None = None, n_out: int | None = None,
            lower: np.ndarray | None = None,
            upper: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, LayerDiagnostics]:
    """Generic particle filtering run, alg. 1 (with layered resampling when ``filtered`` is set).

    1. Update: ``pi = exp(-beta cost)``, normalised (eq. 2.8, 2.9), one ``weight_fn`` call.
    2. Resample: systematic, restricted to the ``filtered`` dimensions (alg. 4; None: all).
    3. Propagate: ``layer.kernel`` with ``std`` (or adaptive std), then clip to the limits.

    Returns the propagated unweighted set (n_out, D), the weights of the input set (N,) and
    the layer's diagnostics.
    """
    t0 = time.perf_counter()
    costs = np.asarray(weight_fn(particles, layer_index), dtype=np.float64)
    t1 = time.perf_counter()
    n = particles.shape[0]
    if costs.shape != (n,):
        raise ValueError(f"layer {layer_index}: weight_fn returned shape {costs.shape}, "
                         f"expected ({n},)")
    if not np.isfinite(costs).any():
        raise ValueError(f"layer {layer_index}: weight_fn returned no finite cost")
    beta = layer.beta if layer.beta is not None else beta_for_survival_rate(
        costs, layer.survival_rate, layer.beta_max)
    weights = annealed_weights(costs, beta)
    ess = effective_sample_size(weights)
    estimate = weights @ particles  # the sample mean (sec. 2.4.1)

    if filtered is None:
        filtered = np.ones(particles.shape[1], dtype=bool)
    if layer.adaptive_scale is not None:
        std = np.where(std > 0.0, layer.adaptive_scale * weighted_std(particles, weights), 0.0)
    resampled = layered_resample(particles, weights, filtered, rng, n_out)
    propagated = clip_to_bounds(layer.kernel(resampled, std, rng), lower, upper)
    t2 = time.perf_counter()
    diag = LayerDiagnostics(layer=layer_index, n_evaluations=n, beta=float(beta), ess=ess,
                            survival_rate=ess / n, min_cost=float(costs[np.isfinite(costs)].min()),
                            estimate=estimate, weight_time_s=t1 - t0, filter_time_s=(t2 - t1))
    return propagated, weights, diag


def lpf_run(particles: np.ndarray, lpf: LayeredFilter, weight_fn: WeightFn,
            rng: np.random.Generator) -> LayeredRunResult:
    """Layered particle filtering run, alg. 5 (the APF of alg. 2 when all layers span all dims).

    For ``l = 0 .. L-1``: GPFRun-with-layered-resampling with ``w_t^l`` and ``K_t^l(Psi_l)``,
    where layer ``l`` resamples the dimensions of ``Psi_0 .. Psi_l`` (alg. 4) and diffuses with
    the std of alg. 3. Then a plain GPFRun with ``w_t^L`` and the inter-frame kernel ``K_t``.

    particles: (N, D) unweighted input set ``x_t``. Deterministic given ``rng``.
    """
    x = np.array(particles, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != lpf.n_dims:
        raise ValueError(f"particles must have shape (N, {lpf.n_dims}), got {x.shape}")
    if not np.isfinite(x).all():
        raise ValueError("particles contain non-finite values")
    steps = lpf.layers + (lpf.final,)
    if steps[0].n_particles is not None and steps[0].n_particles != x.shape[0]:
        raise ValueError(f"first layer weighs {steps[0].n_particles} particles, got {x.shape[0]}")
    filtered = np.zeros(lpf.n_dims, dtype=bool)
    diags = []
    for li, layer in enumerate(steps):
        final = li == len(steps) - 1
        if final:
            filtered[:] = True
            n_out = steps[0].n_particles
        else:
            filtered[np.arange(lpf.n_dims) if layer.dims is None else layer.dims] = True
            n_out = steps[li + 1].n_particles
        weighted = x
        x, weights, diag = gpf_run(weighted, weight_fn, lpf.stds[li], rng, layer, li, filtered,
                                   n_out, lpf.lower, lpf.upper)
        diags.append(diag)
    return LayeredRunResult(estimate=diags[-1].estimate, particles=x, weighted_particles=weighted,
                            weights=weights, layers=tuple(diags))


# ----------------------------------------------------------------------------- builders


def annealed_filter(sigma0: np.ndarray, n_layers: int, n_particles: int | None = None, *,
                    alpha: float | Sequence[float] = 0.5, betas: Sequence[float] | None = None,
                    survival_rate: float = 0.5, adaptive_scale: float | None = None,
                    final_std: np.ndarray | None = None, lower: np.ndarray | None = None,
                    upper: np.ndarray | None = None) -> LayeredFilter:
    """Annealed particle filter (alg. 2) as a layer schedule: ``n_layers`` weightings in all.

    Layers ``k = 0 .. n_layers - 2`` span all dimensions and diffuse with eq. 2.10
    (``alpha``: variance decay rate, scalar or per layer); the last one is the final run with
    the inter-frame kernel (std ``final_std``, default ``sigma0``). ``betas`` (n_layers,)
    fixes beta(k); otherwise each layer picks beta for ``survival_rate``.
    """
    if n_layers < 1:
        raise ValueError("n_layers must be >= 1")
    if betas is not None and len(betas) != n_layers:
        raise ValueError(f"need {n_layers} betas, got {len(betas)}")
    stds = annealing_stds(sigma0, alpha, n_layers - 1)

    def make(k: int, std: np.ndarray | None) -> Layer:
        return Layer(beta=None if betas is None else betas[k], survival_rate=survival_rate,
                     n_particles=n_particles, std=std, adaptive_scale=adaptive_scale)

    layers = tuple(make(k, stds[k]) for k in range(n_layers - 1))
    return LayeredFilter(layers=layers, sigma0=sigma0, final=make(n_layers - 1, final_std),
                         lower=lower, upper=upper)


def hierarchical_filter(blocks: Sequence[np.ndarray], sigma0: np.ndarray,
                        n_particles: int | None = None, *, layers_per_block: int = 1,
                        nu: float = 0.5, survival_rate: float = 0.5,
                        final_std: np.ndarray | None = None, lower: np.ndarray | None = None,
                        upper: np.ndarray | None = None) -> LayeredFilter:
    """Hierarchical particle filter (HPF, sec. 2.2.4): one or more layers per block of dims.

    ``blocks`` are the sub-states ``Psi`` in kinematic-tree order (root first);
    ``layers_per_block`` repeats each block's layer (annealing inside the block, whose std
    decays by ``nu`` per repeat through alg. 3). The weighting function sees the layer index;
    ``weight_fn`` is expected to measure the blocks filtered so far (partitioned sampling,
    sec. 2.2.3). The final run covers all dimensions with the inter-frame kernel.
    """
    layers = tuple(Layer(dims=np.asarray(b), survival_rate=survival_rate, n_particles=n_particles)
                   for b in blocks for _ in range(layers_per_block))
    final = Layer(survival_rate=survival_rate, n_particles=n_particles, std=final_std)
    return LayeredFilter(layers=layers, sigma0=sigma0, nu=nu, final=final, lower=lower,
                         upper=upper)
