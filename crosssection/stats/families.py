"""The distribution families of the paper, one class each, and the registry :data:`FAMILIES`.

Paper: "Statistical distributions in the folding of elastic structures" (Adda-Bedia,
Boudaoud, Boué, Deboeuf), section "Statistical distributions"; location fixed at 0 where the
paper writes none.

=====================  ======================  ==============================================
name                   parameters              density
=====================  ======================  ==============================================
``exponential``        mu                      exp(-x/mu)/mu                          (Eq. (1))
``gamma``              alpha, chi              x^(alpha-1) exp(-x/chi)/(Gamma(alpha) chi^alpha)
                                               (Eq. (3); chi is the *scale*, the mean is alpha chi)
``lognormal``          mu, sigma               mean and std of ln x                   (Eq. (2))
``gaussian``           mu, sigma                                                      (Eq. (17))
``bose_einstein``      alpha, beta, x_lo, x_hi alpha/(exp(beta x) - 1) on [x_lo, x_hi]
``powerlaw_cutoff``    tau, chi, x_min         x^(-tau) exp(-x/chi)/Z on [x_min, inf)
=====================  ======================  ==============================================

Every family is a stateless class (one instance each) carrying its parameter names, support,
MLE (plain and truncated at per-observation detection limits ``c``), density, probability
integral transform, sampler, parameter domain, degeneracy check and the number of parameters
counted in AIC/BIC. Adding a family is adding one ``@register``-ed class.

Bose-Einstein (paper, "Bose-Einstein condensation and annealing"): the form diverges like
1/(beta x) at 0 and is not normalisable on (0, inf); it is normalised on the observed range
[x_lo, x_hi] (x_lo = the truncation cut if one is given, else the sample minimum; x_hi = the
sample maximum) with the closed form Z = [ln(1 - exp(-beta x))]_{x_lo}^{x_hi} / beta and
alpha = 1/Z. Its data-determined endpoints count as parameters (k = 3 without a cut, 2 with).

Power law with exponential cutoff (the paper calls the simulations' void-area law "closer to a
power law"): normalisable for any exponent tau once x >= x_min > 0, with
Z = chi^(1-tau) Gamma(1-tau, x_min/chi) (upper incomplete Gamma, any real first argument).
x_min is the detection limit when there is one, else the sample minimum (then counted as a
parameter, as for Bose-Einstein). For tau < 1 above a detection limit it is the truncated
Gamma law with alpha = 1 - tau, which is then the law to report.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import optimize, special, stats

FAMILIES: dict = {}
FAR = 10.0  # "far outside the data": in standard deviations
FAR_RANGES = 5.0  # ... or in ranges of the data
#: Coefficient of variation (standard deviation over the magnitude of the mean) at or below
#: which a sample counts as constant and a law as a spike. The shape families see the spread
#: through cv^2 (ln <x> - <ln x> ~ cv^2 / 2), which rounding resolves only for cv^2 >> machine
#: epsilon: at this cv the shape keeps about four digits, below it fits return noise or fail.
SPREAD_RTOL = 1e-6


def register(cls):
    """Class decorator: add one instance of a :class:`Family` subclass to :data:`FAMILIES`."""
    fam = cls()
    FAMILIES[fam.name] = fam
    return cls


def no_spread(x) -> bool:
    """Whether the observations ``x`` are constant: their coefficient of variation is at
    most :data:`SPREAD_RTOL` (computed on ``x`` scaled to order one, see
    :func:`binary_exponent`, so that the variance neither overflows nor underflows)."""
    xs = np.ldexp(np.asarray(x, float), -binary_exponent(x))
    return bool(np.std(xs) <= SPREAD_RTOL * abs(np.mean(xs)))


def binary_exponent(x) -> int:
    """The exponent e of the power of two 2^e just above the largest magnitude of ``x``
    (0 when there is none, or it is 0 or not finite): ``np.ldexp(x, -e)`` is of order one
    and exact, so a computation that squares the data neither overflows nor underflows and
    returns the same digits once scaled back with ``np.ldexp(..., e)``."""
    m = float(np.max(np.abs(x))) if np.size(x) else 0.0
    return int(np.frexp(m)[1]) if np.isfinite(m) else 0


# ------------------------------------------------------------------ special functions
def log1mexp(t):
    """log(1 - exp(-t)) for t > 0, accurate at both ends (Maechler 2012)."""
    t = np.asarray(t, dtype=float)
    return np.where(t <= np.log(2.0), np.log(-np.expm1(-np.minimum(t, np.log(2.0)))),
                    np.log1p(-np.exp(-np.maximum(t, np.log(2.0)))))


_SPLIT = 2.0  # continued fraction above, series below (both converge fast there)


def _upper_gamma_cf(s, z, n_terms=300):
    """ln Gamma(s, z) by the Legendre continued fraction (modified Lentz), z >= _SPLIT."""
    tiny = 1e-300
    b = z + 1.0 - s
    c = np.full_like(z, 1.0 / tiny)
    d = 1.0 / b
    h = d.copy()
    for i in range(1, n_terms):
        an = -i * (i - s)
        b = b + 2.0
        d = an * d + b
        d = np.where(np.abs(d) < tiny, tiny, d)
        c = b + an / c
        c = np.where(np.abs(c) < tiny, tiny, c)
        d = 1.0 / d
        delta = d * c
        h = h * delta
        if np.all(np.abs(delta - 1.0) < 4e-16):
            break
    return -z + s * np.log(z) + np.log(h)


def _upper_gamma_cf_scalar(s: float, z: float, n_terms=300) -> float:
    """Scalar :func:`_upper_gamma_cf` in plain floats (it runs once per likelihood call)."""
    b = z + 1.0 - s
    c, d = 1e300, 1.0 / b
    h = d
    for i in range(1, n_terms):
        an = -i * (i - s)
        b += 2.0
        d = an * d + b or 1e-300
        c = b + an / c or 1e-300
        d = 1.0 / d
        h *= d * c
        if abs(d * c - 1.0) < 4e-16:
            break
    return -z + s * math.log(z) + math.log(h)


def _upper_gamma_small_z(s, z, n_terms=40):
    """ln Gamma(s, z) for 0 < z < _SPLIT: Gamma(s, _SPLIT) plus the series of the integral
    from z to _SPLIT, each term (S^a - z^a)/a written with ``exprel`` so that a = 0 is
    regular."""
    lr = np.log(z / _SPLIT)
    total = np.zeros_like(z)
    term = _SPLIT ** s  # (-1)^k S^(s+k) / k!
    for k in range(n_terms):
        total = total + term * (-lr) * special.exprel((s + k) * lr)
        term *= -_SPLIT / (k + 1)
    return np.log(math.exp(_upper_gamma_cf_scalar(s, _SPLIT)) + total)


def _small_z_scalar(s: float, z: float, n_terms=40) -> float:
    """Scalar :func:`_upper_gamma_small_z` in plain floats."""
    lr = math.log(z / _SPLIT)
    total, term = 0.0, _SPLIT ** s
    for k in range(n_terms):
        t = (s + k) * lr
        total += term * (-lr) * (math.expm1(t) / t if t else 1.0)
        term *= -_SPLIT / (k + 1)
    return math.log(math.exp(_upper_gamma_cf_scalar(s, _SPLIT)) + total)


def log_upper_gamma(s: float, z):
    """ln Gamma(s, z), the (non-regularised) upper incomplete Gamma, for real s and z > 0.

    ``scipy.special.gammaincc`` covers s > 0 only (and loses digits as s -> 0); s <= 1 uses a
    continued fraction for z >= 2 and a series for z < 2 (checked against quadrature in the
    tests).
    """
    z = np.atleast_1d(np.asarray(z, dtype=float))
    if s > 1.0:
        with np.errstate(divide="ignore"):
            out = np.log(special.gammaincc(s, z)) + special.gammaln(s)
        bad = ~np.isfinite(out)
        if np.any(bad):  # deep tail
            out[bad] = stats.gamma.logsf(z[bad], s) + special.gammaln(s)
        return out
    if z.size <= 16:  # a few cuts: plain floats beat numpy's per-call overhead
        return np.array([_upper_gamma_cf_scalar(s, v) if v >= _SPLIT
                         else _small_z_scalar(s, v) for v in z.tolist()])
    out = np.empty_like(z)
    big = z >= _SPLIT
    if np.any(big):
        out[big] = _upper_gamma_cf(s, z[big])
    if np.any(~big):
        out[~big] = _upper_gamma_small_z(s, z[~big])
    return out


# ------------------------------------------------------------------ Bose-Einstein law
def be_log_norm(beta, lo, hi):
    """ln Z(beta) with Z = integral_lo^hi dx / (exp(beta x) - 1) (closed form)."""
    beta = float(beta)
    d = log1mexp(beta * np.asarray(hi, float)) - log1mexp(beta * np.asarray(lo, float))
    return np.log(d) - np.log(beta)


def be_logpdf(x, beta, lo, hi):
    """Log density of the Bose-Einstein form normalised on [lo, hi] (lo may be per point)."""
    x = np.asarray(x, float)
    # ln(exp(bx) - 1) = bx + ln(1 - exp(-bx))
    out = -(beta * x + log1mexp(beta * x)) - be_log_norm(beta, lo, hi)
    return np.where((x >= lo) & (x <= hi), out, -np.inf)


def be_cdf(x, beta, lo, hi):
    """Cumulative distribution of the Bose-Einstein form on [lo, hi]."""
    x = np.clip(np.asarray(x, float), lo, hi)
    glo, ghi = log1mexp(beta * np.asarray(lo, float)), log1mexp(beta * hi)
    return (log1mexp(beta * x) - glo) / (ghi - glo)


def be_ppf(u, beta, lo, hi):
    """Inverse of :func:`be_cdf` (closed form)."""
    u = np.asarray(u, float)
    glo, ghi = log1mexp(beta * np.asarray(lo, float)), log1mexp(beta * hi)
    g = glo + u * (ghi - glo)  # = ln(1 - exp(-beta x)) < 0
    return -np.log(-np.expm1(g)) / beta


# ------------------------------------------------------------------ numerical MLE
def _trunc_nll(fam, theta, x, cu, cn):
    """Negative truncated log-likelihood; cuts given as unique values ``cu`` with counts ``cn``
    (images share one cut each, so this evaluates the survival a few times only)."""
    try:
        with np.errstate(all="ignore"):
            ll = np.sum(fam.logpdf_theta(theta, x)) - np.sum(cn * fam.logsf_theta(theta, cu))
    except OverflowError:  # the scalar incomplete Gamma of far-off parameters
        return 1e300
    return -ll if np.isfinite(ll) else 1e300


def fit_truncated_numeric(fam, x, c, theta0=None):
    """Truncated MLE by Nelder-Mead on unconstrained parameters (log of the positive ones)
    of the data rescaled by their median (conditioning). Cold: two starts (the naive fit and
    a broader one, since truncation hides mass below the cut), tight tolerances. Warm
    (``theta0`` given, used by the bootstrap and the GOF refits): one start from ``theta0``,
    relative tolerance 1e-4, far below the bootstrap spread; ~4x fewer evaluations.

    Returns
    -------
    (theta tuple, log-likelihood of the unscaled data)
    """
    sc = float(np.median(x))
    xs, cs = x / sc, c / sc
    cu, cn = np.unique(cs, return_counts=True)
    pos = np.asarray(fam.log_params)

    def f(z):
        th = np.where(pos, np.exp(np.clip(z, -700, 700)), z)
        return _trunc_nll(fam, th, xs, cu, cn)

    if theta0 is not None:
        t0 = fam.rescale(theta0, sc, inverse=True)
        z = np.where(pos, np.log(t0), t0)
        simplex = np.vstack([z, z + np.diag(np.full(z.size, 0.05))])
        best = optimize.minimize(f, z, method="Nelder-Mead",
                                 options={"xatol": 1e-4, "fatol": 1e-6, "maxiter": 300,
                                          "initial_simplex": simplex})
    else:
        t0 = np.array(fam.naive_theta(xs), float)
        z0 = np.where(pos, np.log(t0), t0)
        best = None
        for st in (z0, fam.second_start(z0, xs)):
            r = optimize.minimize(f, st, method="Nelder-Mead",
                                  options={"xatol": 1e-7, "fatol": 1e-9, "maxiter": 4000})
            if best is None or r.fun < best.fun:
                best = r
    th = fam.rescale(np.where(pos, np.exp(best.x), best.x), sc)
    # log-likelihood of the unscaled data: Jacobian of x -> x/sc
    return tuple(map(float, th)), -float(best.fun) - x.size * np.log(sc)


def _outside(loc, scale, lo, hi, name, what="the data"):
    """Why a location parameter lies far outside [lo, hi] ("" when it does not): more than
    FAR standard deviations, or FAR_RANGES data ranges, away. Over the data the fitted bell is
    then an exponential tail, whatever its location and width."""
    dist = lo - loc if loc < lo else loc - hi
    if dist > FAR * scale or dist > FAR_RANGES * (hi - lo):
        side = "below" if loc < lo else "above"
        return (f"{name} = {loc:.4g} lies {dist / scale:.3g} standard deviations "
                f"({dist / (hi - lo):.3g} data ranges) {side} {what}: only a far tail is "
                f"fitted, an exponential in disguise")
    return ""


# ------------------------------------------------------------------ the families
class Family:
    """A distribution family (base class; one instance per family lives in :data:`FAMILIES`).

    Families hold no state: every attribute is a class constant, every method a pure
    function of its arguments.

    Attributes
    ----------
    name : str
        Registry key.
    title : str
        Name in words for reports.
    param_names : tuple of str
        Every reported parameter, in the paper's notation.
    free_names : tuple of str
        The parameters the likelihood is maximised over (``theta``).
    log_params : tuple of bool
        Which of ``free_names`` are positive (optimised on a log scale).
    positive : bool
        Support in x > 0 (non-positive observations make the family inapplicable).
    normalisable_at_zero : bool
        Whether the law can be normalised down to x = 0, so that a detection limit of 0 is
        no limit (False: a cut must be > 0).
    """

    name = ""
    title = ""
    param_names: tuple = ()
    free_names: tuple = ()
    log_params: tuple = ()
    positive = True
    normalisable_at_zero = True

    def k(self, truncated: bool) -> int:
        """Number of parameters counted in AIC/BIC."""
        return len(self.free_names)

    def fit(self, x, c=None, theta0=None):
        """MLE ``(theta, loglik)`` of observations ``x``, truncated at cuts ``c`` (None:
        untruncated); ``theta0`` warm-starts numerical truncated fits."""
        raise NotImplementedError

    def params(self, theta, x, c=None) -> dict:
        """Reported parameters (``param_names``) of a fit."""
        return dict(zip(self.free_names, map(float, theta)))

    def theta(self, params: dict) -> tuple:
        """The free parameters of reported ``params``."""
        return tuple(params[k] for k in self.free_names)

    def pdf(self, params: dict, x):
        """Density of the untruncated law (Bose-Einstein and the power law: on their range)."""
        raise NotImplementedError

    def pit(self, params: dict, x, c=None):
        """Probability integral transform of ``x`` under the (truncated) law."""
        raise NotImplementedError

    def sample(self, params: dict, n: int, c, rng):
        """``n`` draws of the (truncated at ``c``) law."""
        raise NotImplementedError

    def sf(self, params: dict, x):
        """Survival function of the untruncated law."""
        return 1.0 - self.pit(params, np.asarray(x, float))

    def degeneracy(self, params: dict, x, c=None) -> str:
        """Why a fit must not be reported as a law of the data ("" when it may)."""
        return ""

    def positive_names(self) -> tuple:
        """The parameters that must be > 0."""
        return tuple(n for n, pos in zip(self.free_names, self.log_params) if pos)

    def domain(self, params: dict) -> str:
        """Why finite ``params`` lie outside the family's domain ("" when they do not).

        Parameters
        ----------
        params : dict
            Every parameter of the family (``param_names``), as floats.

        Returns
        -------
        str
            The reason, naming the parameter as ``params['name']``.
        """
        for k in self.positive_names():
            if not params[k] > 0:
                return f"params[{k!r}] must be > 0, got {params[k]:.4g}"
        return ""


class ParametricFamily(Family):
    """A family fitted by :func:`fit_truncated_numeric` above a detection limit."""


    def naive_theta(self, x) -> tuple:
        """Untruncated MLE (``scipy.stats`` fit, loc fixed at 0 for the positive laws)."""
        raise NotImplementedError

    def logpdf_theta(self, theta, x):
        """Log density with ``scipy.special`` (no frozen-distribution overhead)."""
        raise NotImplementedError

    def logsf_theta(self, theta, c):
        """Log survival function at the cuts ``c``."""
        raise NotImplementedError

    def rescale(self, theta, sc, inverse=False):
        """Parameters of ``sc * x`` given those of ``x`` (of ``x / sc`` if ``inverse``)."""
        raise NotImplementedError

    def second_start(self, z0, xs):
        """A broader start of the truncated fit (unconstrained parameters)."""
        return z0 - np.where(np.asarray(self.log_params), -np.log(1.5), np.std(xs))


class BoundLaw:
    """A ``scipy.stats`` law with its parameters bound: the methods of its frozen
    distribution (``pdf``, ``logpdf``, ``cdf``, ``sf``, ``logsf``, ``ppf``, ``isf``, ``rvs``),
    each the same call of the law itself with the same arguments, so the same numbers; any
    other attribute is the frozen distribution's.

    Written because scipy builds every frozen distribution as a new instance of its class,
    docstrings included: 0.5 ms each, and the bootstraps and goodness-of-fit tests of one
    ensemble freeze tens of thousands (51 000 for the report of the five sample scans, which
    took 50 s with frozen distributions and takes 32 s with these, the same tables).
    """

    __slots__ = ("rv", "args", "kwds")

    def __init__(self, rv, *args, **kwds):
        self.rv, self.args, self.kwds = rv, args, kwds

    def pdf(self, x):
        return self.rv.pdf(x, *self.args, **self.kwds)

    def logpdf(self, x):
        return self.rv.logpdf(x, *self.args, **self.kwds)

    def cdf(self, x):
        return self.rv.cdf(x, *self.args, **self.kwds)

    def sf(self, x):
        return self.rv.sf(x, *self.args, **self.kwds)

    def logsf(self, x):
        return self.rv.logsf(x, *self.args, **self.kwds)

    def ppf(self, q):
        return self.rv.ppf(q, *self.args, **self.kwds)

    def isf(self, q):
        return self.rv.isf(q, *self.args, **self.kwds)

    def rvs(self, size=None, random_state=None):
        return self.rv.rvs(*self.args, size=size, random_state=random_state, **self.kwds)

    def __getattr__(self, name):
        # anything else of a frozen distribution (mean, std, support, ...): from one
        if name in BoundLaw.__slots__ or name.startswith("__"):
            raise AttributeError(name)
        return getattr(self.rv(*self.args, **self.kwds), name)


class ScipyFamily(ParametricFamily):
    """A family backed by a ``scipy.stats`` distribution (loc 0 for the positive ones).

    ``rv`` and ``known`` are what ``scipy.stats.goodness_of_fit`` needs for the
    untruncated test.
    """

    rv = None
    known = {"loc": 0.0}
    #: the parameter that sets the relative width of the law (None: the width is fixed)
    width_name = None
    #: whether the untruncated fit squares the data (a variance), which overflows or
    #: underflows at extreme scales unless the data are scaled first
    squares_data = False

    def frozen(self, params: dict) -> BoundLaw:
        """The ``scipy.stats`` law with ``params`` bound (:class:`BoundLaw`)."""
        raise NotImplementedError

    def std(self, params: dict) -> float:
        """Standard deviation of the untruncated law, written so that it neither overflows
        nor underflows where the law's scale does not (``scipy.stats`` squares the scale)."""
        raise NotImplementedError

    def cv(self, params: dict) -> float:
        """Coefficient of variation (standard deviation over the magnitude of the mean) of
        the untruncated law; inf for a mean of 0."""
        raise NotImplementedError

    def domain(self, params):
        """Also out of the domain: a law narrower than :data:`SPREAD_RTOL` of its mean, a
        spike no sample with a spread comes from and no refit resolves."""
        why = super().domain(params)
        if why or self.width_name is None:
            return why
        with np.errstate(all="ignore"):
            cv = float(self.cv(params))
        if not cv > SPREAD_RTOL:
            k = self.width_name
            return (f"params[{k!r}] = {params[k]:.4g} makes the law a spike: its standard "
                    f"deviation is {cv:.3g} of its mean, at or below the {SPREAD_RTOL:g} "
                    f"under which a sample counts as constant")
        return ""

    def fit(self, x, c=None, theta0=None):
        if c is None:
            theta = self.naive_theta(x)
            return theta, float(np.sum(self.frozen(self.params(theta, x)).logpdf(x)))
        return fit_truncated_numeric(self, x, c, theta0)

    def pdf(self, params, x):
        return self.frozen(params).pdf(np.asarray(x, float))

    def sf(self, params, x):
        return self.frozen(params).sf(x)

    def pit(self, params, x, c=None):
        d = self.frozen(params)
        if c is None:
            return d.cdf(x)
        return 1.0 - d.sf(x) / d.sf(c)

    def sample(self, params, n, c, rng):
        u = rng.uniform(size=n)
        d = self.frozen(params)
        if c is None:
            return d.ppf(u)
        return d.isf((1.0 - u) * d.sf(c))


@register
class Exponential(ScipyFamily):
    """exp(-x/mu)/mu (paper, Eq. (1)). Truncated MLE in closed form: memoryless, x - c is
    exponential with the same mu (the paper's note on <l> against mu)."""

    name = "exponential"
    title = "exponential"
    param_names = ("mu",)
    free_names = ("mu",)
    log_params = (True,)
    rv = stats.expon

    def frozen(self, params):
        return BoundLaw(stats.expon, scale=params["mu"])

    def std(self, params):
        return params["mu"]

    def cv(self, params):
        return 1.0

    def naive_theta(self, x):
        return (float(np.mean(x)),)

    def logpdf_theta(self, theta, x):
        return -x / theta[0] - np.log(theta[0])

    def logsf_theta(self, theta, c):
        return -c / theta[0]

    def rescale(self, theta, sc, inverse=False):
        th = np.array(theta, float)
        return th / sc if inverse else th * sc

    def fit(self, x, c=None, theta0=None):
        if c is None:
            return super().fit(x)
        mu = float(np.mean(x - c))
        return (mu,), float(np.sum(-np.log(mu) - (x - c) / mu))


@register
class Gamma(ScipyFamily):
    """x^(alpha-1) exp(-x/chi)/(Gamma(alpha) chi^alpha) (paper, Eq. (3); chi the scale)."""

    name = "gamma"
    title = "Gamma"
    param_names = ("alpha", "chi")
    free_names = ("alpha", "chi")
    log_params = (True, True)
    rv = stats.gamma
    width_name = "alpha"  # coefficient of variation 1/sqrt(alpha)

    def frozen(self, params):
        return BoundLaw(stats.gamma, params["alpha"], scale=params["chi"])

    def std(self, params):
        return math.sqrt(params["alpha"]) * params["chi"]

    def cv(self, params):
        return 1.0 / math.sqrt(params["alpha"])

    def naive_theta(self, x):
        a, _, scale = stats.gamma.fit(x, floc=0)
        return (a, scale)

    def logpdf_theta(self, theta, x):
        a, chi = theta
        return special.xlogy(a - 1, x) - x / chi - special.gammaln(a) - a * np.log(chi)

    def logsf_theta(self, theta, c):
        a, chi = theta
        sf = special.gammaincc(a, c / chi)
        with np.errstate(divide="ignore"):
            out = np.log(sf)
        bad = ~np.isfinite(out)
        if np.any(bad):  # deep tail: scipy's asymptotics
            out[bad] = stats.gamma.logsf(c[bad], a, scale=chi)
        return out

    def rescale(self, theta, sc, inverse=False):
        th = np.array(theta, float)
        th[1] = th[1] / sc if inverse else th[1] * sc
        return th

    def second_start(self, z0, xs):
        return np.array([np.log(0.5), np.log(np.mean(xs) * 2)])

    def degeneracy(self, params, x, c=None):
        a, chi = params["alpha"], params["chi"]
        if a < 1e-3:
            return (f"alpha = {a:.3g} at its bound 0: the data fall faster than 1/x "
                    f"(a power law, see powerlaw_cutoff)")
        if chi > FAR ** 2 * np.max(x):
            return (f"chi = {chi:.4g} is far beyond the largest observation "
                    f"({np.max(x):.4g}): no cutoff in the data")
        return ""


@register
class LogNormal(ScipyFamily):
    """Log-normal (paper, Eq. (2)): mu and sigma are the mean and std of ln x."""

    name = "lognormal"
    title = "log-normal"
    param_names = ("mu", "sigma")
    free_names = ("mu", "sigma")
    log_params = (False, True)
    rv = stats.lognorm
    width_name = "sigma"

    def frozen(self, params):
        return BoundLaw(stats.lognorm, params["sigma"], scale=np.exp(params["mu"]))

    def std(self, params):
        s2 = params["sigma"] ** 2
        return float(np.exp(params["mu"] + 0.5 * s2 + 0.5 * np.log(np.expm1(s2))))

    def cv(self, params):
        return float(np.sqrt(np.expm1(params["sigma"] ** 2)))

    def naive_theta(self, x):
        s, _, scale = stats.lognorm.fit(x, floc=0)
        return (np.log(scale), s)

    def logpdf_theta(self, theta, x):
        mu, sg = theta
        lx = np.log(x)
        return -0.5 * ((lx - mu) / sg) ** 2 - lx - np.log(sg) - 0.5 * np.log(2 * np.pi)

    def logsf_theta(self, theta, c):
        mu, sg = theta
        return special.log_ndtr(-(np.log(c) - mu) / sg)

    def rescale(self, theta, sc, inverse=False):
        th = np.array(theta, float)
        th[0] = th[0] - np.log(sc) if inverse else th[0] + np.log(sc)
        return th

    def sample(self, params, n, c, rng):
        if c is None:
            return super().sample(params, n, c, rng)
        # inverse survival in log space, so that cuts deep in the tail stay finite
        u = rng.uniform(size=n)
        mu, sg = params["mu"], params["sigma"]
        z = special.ndtri_exp(np.log1p(-u) + special.log_ndtr(-(np.log(c) - mu) / sg))
        return np.exp(mu - sg * z)

    def degeneracy(self, params, x, c=None):
        lx = np.log(x)
        span = max(float(np.ptp(lx)), np.finfo(float).eps)
        far = _outside(params["mu"], params["sigma"], lx.min(), lx.max(), "mu",
                       "the observed ln x")
        if not far and params["sigma"] > FAR * span:
            return (f"sigma = {params['sigma']:.3g} is far beyond the spread of ln x "
                    f"({span:.3g}): the law is flat over the data")
        return far


@register
class Gaussian(ScipyFamily):
    """Gaussian (paper, Eq. (17)); truncated at the detection limit when there is one."""

    name = "gaussian"
    title = "Gaussian"
    param_names = ("mu", "sigma")
    free_names = ("mu", "sigma")
    log_params = (False, True)
    positive = False
    rv = stats.norm
    known = {}
    width_name = "sigma"
    squares_data = True

    def frozen(self, params):
        return BoundLaw(stats.norm, params["mu"], params["sigma"])

    def std(self, params):
        return params["sigma"]

    def cv(self, params):
        return params["sigma"] / abs(params["mu"]) if params["mu"] else math.inf

    def naive_theta(self, x):
        # the variance squares the data (squares_data): fitted on x / 2^e, of order one
        e = binary_exponent(x)
        m, s = stats.norm.fit(np.ldexp(x, -e))
        return (float(np.ldexp(m, e)), float(np.ldexp(s, e)))

    def logpdf_theta(self, theta, x):
        mu, sg = theta
        return -0.5 * ((x - mu) / sg) ** 2 - np.log(sg) - 0.5 * np.log(2 * np.pi)

    def logsf_theta(self, theta, c):
        mu, sg = theta
        return special.log_ndtr(-(c - mu) / sg)

    def rescale(self, theta, sc, inverse=False):
        th = np.array(theta, float)
        return th / sc if inverse else th * sc

    def sample(self, params, n, c, rng):
        if c is None:
            return super().sample(params, n, c, rng)
        u = rng.uniform(size=n)
        mu, sg = params["mu"], params["sigma"]
        return mu - sg * special.ndtri_exp(np.log1p(-u) + special.log_ndtr(-(c - mu) / sg))

    def degeneracy(self, params, x, c=None):
        span = max(float(np.ptp(x)), np.finfo(float).eps)
        far = _outside(params["mu"], params["sigma"], np.min(x), np.max(x), "mu")
        if not far and params["sigma"] > FAR * span:
            return (f"sigma = {params['sigma']:.3g} is far beyond the data range "
                    f"({span:.3g}): the law is flat over the data")
        return far


@register
class BoseEinstein(Family):
    """alpha/(exp(beta x) - 1) normalised on [x_lo, x_hi] (see the module docstring)."""

    name = "bose_einstein"
    title = "Bose-Einstein"
    param_names = ("alpha", "beta", "x_lo", "x_hi")
    free_names = ("beta",)
    log_params = (True,)
    normalisable_at_zero = False  # 1/(beta x) near 0
    search = (-12.0, 6.0)  # ln(beta <x>): beta x from 1/x-like to exponential-like

    def k(self, truncated):
        return 2 if truncated else 3  # beta + the data-determined endpoints

    def fit(self, x, c=None, theta0=None):
        lo = float(np.min(x)) if c is None else c
        hi = float(np.max(x))
        span = np.log(float(np.mean(x)))

        def nll(lb):
            return -float(np.sum(be_logpdf(x, np.exp(lb), lo, hi)))

        res = optimize.minimize_scalar(nll, bounds=(self.search[0] - span,
                                                    self.search[1] - span),
                                       method="bounded", options={"xatol": 1e-7})
        return (float(np.exp(res.x)),), -float(res.fun)

    def params(self, theta, x, c=None):
        lo = float(np.min(x)) if c is None else float(np.min(c))
        hi = float(np.max(x))
        beta = float(theta[0])
        return {"alpha": float(np.exp(-be_log_norm(beta, lo, hi))), "beta": beta,
                "x_lo": lo, "x_hi": hi}

    def positive_names(self):
        return ("alpha", "beta", "x_lo", "x_hi")

    def domain(self, params):
        why = super().domain(params)
        if not why and not params["x_lo"] < params["x_hi"]:
            why = (f"params['x_lo'] must be below params['x_hi'] "
                   f"({params['x_hi']:.4g}), got {params['x_lo']:.4g}")
        return why

    def pdf(self, params, x):
        return np.exp(be_logpdf(np.asarray(x, float), params["beta"], params["x_lo"],
                                params["x_hi"]))

    def pit(self, params, x, c=None):
        lo = params["x_lo"] if c is None else c
        return be_cdf(x, params["beta"], lo, params["x_hi"])

    def sample(self, params, n, c, rng):
        lo = params["x_lo"] if c is None else c
        return be_ppf(rng.uniform(size=n), params["beta"], lo, params["x_hi"])

    def degeneracy(self, params, x, c=None):
        bx = params["beta"] * float(np.mean(x))
        if abs(np.log(bx) - self.search[0]) < 1e-3 or params["beta"] * params["x_hi"] < 1e-2:
            return (f"beta = {params['beta']:.3g}: beta x << 1 over the data, so the law is "
                    f"1/x and beta (and alpha = {params['alpha']:.3g}) are undetermined")
        if abs(np.log(bx) - self.search[1]) < 1e-3:
            return f"beta = {params['beta']:.3g} at the upper end of its search range"
        return ""


@register
class PowerLawCutoff(ParametricFamily):
    """x^(-tau) exp(-x/chi)/Z on [x_min, inf) (see the module docstring)."""

    name = "powerlaw_cutoff"
    title = "power law with exponential cutoff"
    param_names = ("tau", "chi", "x_min")
    free_names = ("tau", "chi")
    log_params = (False, True)
    normalisable_at_zero = False  # x_min > 0 (module docstring)

    def k(self, truncated):
        return 2 if truncated else 3  # tau, chi + the sample minimum as x_min

    def naive_theta(self, x):
        a, _, scale = stats.gamma.fit(x, floc=0)
        return (1.0 - a, scale)

    def logpdf_theta(self, theta, x):
        """Unnormalised: the normalisation is the 'survival' at the cut, ln Z(c)."""
        tau, chi = theta
        return -tau * np.log(x) - x / chi

    def logsf_theta(self, theta, c):
        """ln Z(c) = ln integral_c^inf x^(-tau) exp(-x/chi) dx."""
        tau, chi = theta
        return (1.0 - tau) * np.log(chi) + log_upper_gamma(1.0 - tau, np.asarray(c) / chi)

    def rescale(self, theta, sc, inverse=False):
        th = np.array(theta, float)
        th[1] = th[1] / sc if inverse else th[1] * sc
        return th

    def second_start(self, z0, xs):
        return np.array([2.0, np.log(10.0 * np.max(xs))])

    def positive_names(self):
        return ("chi", "x_min")

    def _cuts(self, x, c):
        return np.full(np.shape(x), float(np.min(x))) if c is None else np.asarray(c, float)

    def fit(self, x, c=None, theta0=None):
        return fit_truncated_numeric(self, x, self._cuts(x, c), theta0)

    def params(self, theta, x, c=None):
        return {"tau": float(theta[0]), "chi": float(theta[1]),
                "x_min": float(np.min(self._cuts(x, c)))}

    def pdf(self, params, x):
        x = np.asarray(x, float)
        th = (params["tau"], params["chi"])
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.exp(self.logpdf_theta(th, x) - self.logsf_theta(th, params["x_min"]))
        return np.where(x >= params["x_min"], out, 0.0)

    def _log_sf(self, params, x, c):
        th = (params["tau"], params["chi"])
        c = params["x_min"] if c is None else c
        return self.logsf_theta(th, np.maximum(x, c)) - self.logsf_theta(th, c)

    def pit(self, params, x, c=None):
        return -np.expm1(self._log_sf(params, np.asarray(x, float), c))

    def sample(self, params, n, c, rng):
        """Inverse survival function by bisection on ln x (vectorised)."""
        target = np.log1p(-rng.uniform(size=n))
        c = np.broadcast_to(params["x_min"] if c is None else c, (n,)).astype(float)
        lo = np.log(c)
        hi = lo + 1.0
        while True:  # bracket: the survival at exp(hi) is below every target
            short = self._log_sf(params, np.exp(hi), c) > target
            if not np.any(short):
                break
            hi = np.where(short, hi + 2.0, hi)
        for _ in range(48):  # bracket width < 2^-40 in ln x
            mid = 0.5 * (lo + hi)
            above = self._log_sf(params, np.exp(mid), c) > target
            lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
        return np.exp(0.5 * (lo + hi))

    def degeneracy(self, params, x, c=None):
        if c is not None and params["tau"] < 1.0:
            return (f"tau = {params['tau']:.3g} < 1 above the detection limit: the same law "
                    f"as the truncated Gamma with alpha = 1 - tau = {1 - params['tau']:.3g}")
        if params["chi"] > FAR ** 2 * np.max(x):
            return (f"chi = {params['chi']:.4g} is far beyond the largest observation "
                    f"({np.max(x):.4g}): a pure power law, the cutoff is not seen")
        return ""
