"""The discrete-time model x+ = f(x, u, w), written once as CasADi expressions."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import casadi as ca
import numpy as np

from ._validate import as_boxes, as_points
from .exceptions import (
    DimensionError,
    FreeSymbolError,
    ModelError,
    UnboundedSetError,
    UnsupportedOperationError,
)
from .interval._derivative import JacobianInclusion, ParamFunction, ParamGraph, exact_function
from .interval.compiler import InclusionFunction, inclusion
from .sets.box import Box

__all__ = ["Model"]

_WRT = ("x", "u", "w")


def _is_symbolic_vector(s: Any) -> bool:
    return s.is_column() and s.is_valid_input() and (s.numel() == 0 or s.is_symbolic()
                                                     or all(s[i].is_symbolic()
                                                            for i in range(s.numel())))


def _check_name(name: Any) -> str:
    """The model's name, refused unless CasADi accepts it, and its derived function names
    (``<name>_f``...), as a Function name: a letter first, then letters, digits and single
    underscores, no trailing underscore."""
    text = str(name)
    if not (ca.Function.check_name(text) and ca.Function.check_name(text + "_f")):
        raise ModelError(f"model name {text!r} is not usable: the functions generated from "
                         "the model carry it, so it must start with a letter and contain "
                         "only letters, digits and single underscores, not ending with one "
                         "(e.g. 'my_model')")
    return text


def _check_symbol(s: Any, name: str) -> None:
    if not isinstance(s, ca.SX):
        raise TypeError(f"{name} must be a casadi.SX column of symbols; got {type(s).__name__}")
    if not s.is_column():
        raise DimensionError(f"{name} must be a column vector; got shape {s.shape}")
    if not _is_symbolic_vector(s):
        raise ModelError(f"{name} must consist of pure symbols (e.g. casadi.SX.sym('{name}', n)),"
                         " not expressions")


def _to_sx(x: Any, u: Any, w: Any, f: Any) -> tuple[ca.SX, ca.SX, ca.SX | None, ca.SX]:
    """Convert MX symbols/expression to SX by building and expanding a Function."""
    mx = [v for v in (x, u, w, f) if isinstance(v, ca.MX)]
    if not mx:
        return x, u, w, f
    if not all(isinstance(v, ca.MX) for v in (x, u, f) if v is not None) or (
            w is not None and not isinstance(w, ca.MX)):
        raise TypeError("x, u, w and f must all be casadi.SX (or all casadi.MX, which is "
                        "converted to SX); got a mixture")
    ins = [x, u] + ([w] if w is not None else [])
    _check_free(f, ins, "f")
    try:
        fun = ca.Function("f_mx", ins, [f]).expand()
    except Exception as exc:
        raise TypeError(
            "the MX model could not be converted to SX (it may contain calls that have no "
            f"SX form: {exc}); write the model with casadi.SX symbols") from exc
    xs = ca.SX.sym("x", x.shape[0])
    us = ca.SX.sym("u", u.shape[0])
    ws = ca.SX.sym("w", w.shape[0]) if w is not None else None
    fs = fun(*([xs, us] + ([ws] if ws is not None else [])))
    return xs, us, ws, fs


def _check_free(expr: Any, declared: list[Any], what: str) -> None:
    """Raise FreeSymbolError when expr depends on symbols outside ``declared``."""
    allowed = set()
    for v in declared:
        if v is None:
            continue
        for s in ca.symvar(v):
            allowed.add(s.__hash__())
    free = [s for s in ca.symvar(expr) if s.__hash__() not in allowed]
    if free:
        raise FreeSymbolError(
            f"{what} depends on symbols that are not declared as x, u or w: "
            + ", ".join(str(s) for s in free)
            + "; substitute numeric values for parameters or declare uncertain ones as w")


def _as_model_box(B: Any, d: int, name: str) -> Box:
    if isinstance(B, Box):
        box = B
    else:
        arr = np.asarray(B, dtype=float) if not isinstance(B, tuple) else None
        if isinstance(B, tuple) and len(B) == 2:
            box = Box(*B)
        elif arr is not None and arr.ndim == 2 and arr.shape[1] == 2:
            box = Box(arr[:, 0], arr[:, 1])
        else:
            raise TypeError(f"{name} must be a Box, a (d, 2) array or a (lo, hi) pair")
    if box.dim != d:
        raise DimensionError(f"{name} has the wrong dimension; expected {d} instead of {box.dim}")
    if not box.is_bounded():
        raise UnboundedSetError(f"{name} must be bounded; got {box!r}")
    return box


def _as_names(names: Any, d: int, what: str, prefix: str) -> tuple[str, ...]:
    """Names of the d components of a variable: given ones checked, or ``prefix1..prefixd``."""
    if names is None:
        return tuple(f"{prefix}{i + 1}" for i in range(d))
    if isinstance(names, str):
        names = [names]
    try:
        names = list(names)
    except TypeError:
        raise TypeError(f"{what} must be a sequence of {d} strings; got "
                        f"{type(names).__name__}") from None
    if len(names) != d:
        raise DimensionError(f"{what} has the wrong number of names; expected {d} (one per "
                             f"component) instead of {len(names)}: {names}")
    for v in names:
        if not isinstance(v, str) or not v.strip():
            raise TypeError(f"{what} must hold non-empty strings; got {v!r}")
    return tuple(names)


def _as_units(units: Any, names: tuple[str, ...]) -> dict[str, str]:
    """``{name: unit}`` for the named variables that have a unit (empty units dropped)."""
    if units is None:
        return {}
    if not isinstance(units, Mapping):
        raise TypeError("units must be a mapping from variable names to unit strings, e.g. "
                        f"{{'T': 'K'}}; got {type(units).__name__}")
    out: dict[str, str] = {}
    for key, unit in units.items():
        if key not in names:
            raise ValueError(f"units names an unknown variable {key!r}; the variables are "
                             f"{', '.join(names)}")
        if not isinstance(unit, str):
            raise TypeError(f"the unit of {key!r} must be a string; got {unit!r}")
        if unit.strip():
            out[str(key)] = unit.strip()
    return out


def _as_dt(dt: Any) -> float | None:
    """The sampling time in seconds: a positive finite number, or None."""
    if dt is None:
        return None
    if isinstance(dt, (bool, np.bool_)) or not isinstance(dt, (int, float, np.integer,
                                                                 np.floating)):
        raise TypeError(f"dt must be a number of seconds or None; got {type(dt).__name__}")
    value = float(dt)
    if not np.isfinite(value) or value <= 0:
        raise ValueError(f"dt must be a positive finite number of seconds (or None when the "
                         f"model has no sampling time); got {dt}")
    return value


class Model:
    """Discrete-time model ``x+ = f(x, u, w)`` with state, input and disturbance boxes.

    Parameters
    ----------
    x : casadi.SX, shape (n, 1)
        State symbols.
    u : casadi.SX, shape (m, 1)
        Input symbols (``m = 0`` allowed: ``casadi.SX.sym("u", 0)``).
    f : casadi.SX, shape (n, 1)
        Successor state as an expression of ``x``, ``u`` and ``w`` only.
    w : casadi.SX, shape (l, 1), optional
        Uncertain parameters / disturbances. Requires ``W``.
    X, U, W : Box or array_like (d, 2) or (lo, hi)
        Bounded constraint boxes of x, u and the range of w.
    name : str
        Used in Function names and generated code.
    state_names, input_names, disturbance_names : sequence of str, optional
        One name per component of x (n), u (m) and w (l), used in figures and summaries;
        default ``x1..xn``, ``u1..um``, ``w1..wl``. All names must differ from one another.
    units : mapping of str to str, optional
        Unit of some of the named variables, e.g. ``{"T": "K"}``; a variable without an
        entry has no unit (figures then show its name alone). Default: no units.
    dt : float, optional
        Sampling time in seconds (the time between x(k) and x(k + 1)); figures then show
        time in seconds, otherwise the step k. Default None: no sampling time.

    MX symbols and expressions are accepted and converted to SX (``Function.expand``).

    Attributes
    ----------
    state_names, input_names, disturbance_names : tuple of str
        Lengths n, m and l.
    units : dict of str to str
        The given units, by variable name.
    dt : float or None
        Sampling time in seconds.
    discretisation : str
        What the map is, and so what its certificates are about (read-only; see
        :attr:`discretisation`): ``"discrete model"`` unless built by :meth:`from_ode`.

    Raises
    ------
    FreeSymbolError
        ``f`` depends on symbols other than ``x``, ``u``, ``w``.
    DimensionError
        Shapes of ``f`` or a box do not match, or a list of names has the wrong length.
    TypeError
        A name or unit that is not a string, ``dt`` that is not a number.
    ValueError
        ``dt <= 0`` (or not finite), repeated names, a unit of an unknown variable.
    ModelError
        ``w`` without ``W`` (or ``W`` without ``w``), non-symbolic ``x``/``u``/``w``.
    EmptySetError, InvalidBoundsError, UnboundedSetError
        A box with ``lo > hi``, NaN or infinite bounds.

    Examples
    --------
    >>> import casadi as ca, casadi_cmpc as cm
    >>> x = ca.SX.sym("x", 2); u = ca.SX.sym("u")
    >>> f = ca.vertcat(x[0] + 0.1 * x[1], x[1] + 0.1 * u)
    >>> model = cm.Model(x=x, u=u, f=f, X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]))
    >>> model.n, model.m, model.l
    (2, 1, 0)
    >>> model.is_linear
    True
    >>> model = cm.Model(x=x, u=u, f=f, X=cm.Box([-1, -1], [1, 1]), U=cm.Box([-1], [1]),
    ...                  state_names=["p", "v"], units={"p": "m", "v": "m/s"}, dt=0.1)
    >>> model.state_names, model.input_names, model.units["v"], model.dt
    (('p', 'v'), ('u1',), 'm/s', 0.1)
    """

    def __init__(self, x: Any, u: Any, f: Any, w: Any = None, X: Any = None, U: Any = None,
                 W: Any = None, name: str = "model", *, state_names: Any = None,
                 input_names: Any = None, disturbance_names: Any = None, units: Any = None,
                 dt: Any = None) -> None:
        if u is None:
            u = ca.SX.sym("u", 0) if not isinstance(x, ca.MX) else ca.MX.sym("u", 0)
        x, u, w, f = _to_sx(x, u, w, f)
        _check_symbol(x, "x")
        _check_symbol(u, "u")
        if w is not None:
            _check_symbol(w, "w")
            if w.numel() == 0:
                w = None
        if not isinstance(f, ca.SX):
            try:
                f = ca.SX(f)
            except Exception as exc:
                raise TypeError(f"f must be a casadi.SX expression; got {type(f).__name__}"
                                ) from exc
        n, m = x.numel(), u.numel()
        if n == 0:
            raise DimensionError("the state x must have at least one component")
        if f.numel() != n or not (f.is_column() or f.is_row()):
            raise DimensionError(
                f"f must be a vector with as many elements as x; expected {n} instead of "
                f"shape {f.shape}")
        f = ca.reshape(ca.densify(f), n, 1)
        if w is not None and W is None:
            raise ModelError("w is given but its range W is missing; pass W=cm.Box(lo, hi)")
        if w is None and W is not None:
            raise ModelError("W is given but there is no disturbance symbol w")
        if X is None:
            raise ModelError("the state box X is required (e.g. X=cm.Box(lo, hi))")
        if U is None:
            if m > 0:
                raise ModelError("the input box U is required (e.g. U=cm.Box(lo, hi))")
            U = Box(np.zeros(0), np.zeros(0))
        _check_free(f, [x, u, w], "f")
        self.x, self.u, self.w, self.f = x, u, w, f
        self.name = _check_name(name)
        self.X = _as_model_box(X, n, "X")
        self.U = _as_model_box(U, m, "U")
        self.W = _as_model_box(W, w.numel(), "W") if w is not None else None
        self.state_names = _as_names(state_names, n, "state_names", "x")
        self.input_names = _as_names(input_names, m, "input_names", "u")
        self.disturbance_names = _as_names(disturbance_names, 0 if w is None else w.numel(),
                                           "disturbance_names", "w")
        every = self.state_names + self.input_names + self.disturbance_names
        repeated = sorted({v for v in every if every.count(v) > 1})
        if repeated:
            raise ValueError(f"the names of x, u and w must all differ; repeated: "
                             f"{', '.join(repeated)}")
        self.units = _as_units(units, every)
        self.dt = _as_dt(dt)
        self.law: ca.SX | None = None  # set by closed_loop
        self.input_box: Box | None = None  # U of the open-loop model, set by closed_loop
        # closed loops: f(x, law(x), w) in x, w and parameter symbols standing for the
        # literals of f and the law, with their values (see interval_function); None for a
        # model given by its expressions
        self._exact_f: ca.SX | None = None
        self._exact_params: tuple[ca.SX, np.ndarray] | None = None
        self._cache: dict[Any, Any] = {}
        # what the model's certificates are about (see ``discretisation``); from_ode sets
        # it, closed_loop keeps it
        self._discretisation = "discrete model"
        self._validation: dict[str, Any] | None = None  # a validated ODE model: its data

    # ----------------------------------------------------------- what it models
    @property
    def discretisation(self) -> str:
        """What the model's map is, and so what every certificate computed from it is about.

        ``"discrete model"`` for a model given by its successor ``f``; for
        :meth:`from_ode`: ``"the Euler map of an ODE (no error bound)"`` or ``"the RK4 map
        of an ODE (no error bound)"`` (certificates are about that map, not the plant), or
        ``"the sampled-data ODE (validated Taylor, order k, dt = ..., zero-order hold, w
        constant over the sample)"``: the interval evaluators of such a model enclose the
        true flow of the ODE (see :meth:`from_ode`). A closed loop keeps the string of its
        open-loop model.
        """
        return self._discretisation

    @property
    def is_validated(self) -> bool:
        """True for a validated sampled-data ODE model (``from_ode(method="taylor")``) and
        its closed loops: the interval evaluators enclose the true flow."""
        return self._validation is not None

    @property
    def validation(self) -> dict[str, Any] | None:
        """Data of a validated ODE model (None otherwise): ``order``, ``dt`` (time units of
        the ODE), ``domain`` (the validated domain D over (x, u, w), shape (n + m + l, 2);
        boxes leaving it give ``[-inf, inf]``), ``centre``, ``rho`` (n, 2) and ``M``
        (n, n + m + l, 2) of the remainder ``rho + M (z - centre)``, ``apriori`` (n, 2),
        an enclosure of all trajectories from D over one sample, and
        ``remainder_width``, the largest width of the remainder over D."""
        return None if self._validation is None else dict(self._validation)

    def interval_key(self) -> str:
        """A hash (20 hex digits) of everything an interval evaluation of the model reads:
        its interval source (:attr:`interval_function`, serialized) and the intervals of
        its parameters. Two validated models with the same Taylor map but different
        remainders (other boxes, order, dt) differ here, not in a hash of :attr:`function`;
        key cached certificates with it."""
        import hashlib

        def build() -> str:
            src = self.interval_function
            h = hashlib.sha256()
            if isinstance(src, ParamFunction):
                h.update(src.function.serialize().encode())
                h.update(np.ascontiguousarray(src.bounds).tobytes())
                h.update(np.asarray(sorted(src.derived), dtype=np.int64).tobytes())
            else:
                h.update(src.serialize().encode())
            return h.hexdigest()[:20]

        return self._cached("interval_key", build)

    def interval_expr(self) -> tuple[ca.SX, ca.SX, np.ndarray]:
        """The successor as an expression for interval evaluators, with its parameters.

        Returns ``(expr, params, bounds)``: ``expr`` (n, 1) in :attr:`x`, :attr:`u`,
        :attr:`w` (``casadi.SX.sym("w", 0)`` without disturbance) and ``params`` (q, 1);
        ``bounds`` (q, 2) the interval of every parameter. Every literal constant is a
        parameter (exact, ``lo == hi``), constants CasADi may have rounded while composing
        are widened, and a validated ODE model's remainder terms are interval valued
        (``lo < hi``). Build composed evaluators as::

            expr, P, Pb = model.interval_expr()
            H = casadi.SX.sym("H", r, model.n)
            g = casadi.Function("rows", [model.x, model.u, model._w_sym,
                                         casadi.vertcat(casadi.vec(H), P)],
                                [casadi.mtimes(H, expr)])
            vals = numpy.vstack([numpy.repeat(A.ravel(order="F")[:, None], 2, axis=1), Pb])
            F = InclusionFunction(ParamFunction(g, 3, vals), "centered")

        Use it (or :meth:`interval_map`) instead of :attr:`f` wherever an interval
        evaluator is compiled: :attr:`f` of a validated model is only the Taylor
        polynomial, and of a closed loop a rounded composition.
        """
        def build() -> tuple[ca.SX, ca.SX, np.ndarray]:
            pg = ParamGraph(self.interval_function)
            expr = ca.Function("expr", pg.inputs + [pg.params], pg.outputs).call(
                [self.x, self.u, self._w_sym, pg.params])[0]
            return expr, pg.params, pg.bounds.copy()

        return self._cached("interval_expr", build)

    # ------------------------------------------------------------------ sizes
    @property
    def n(self) -> int:
        """Number of states."""
        return int(self.x.numel())

    @property
    def m(self) -> int:
        """Number of inputs."""
        return int(self.u.numel())

    @property
    def l(self) -> int:  # noqa: E743
        """Number of disturbances (0 without w)."""
        return 0 if self.w is None else int(self.w.numel())

    @property
    def _w_sym(self) -> ca.SX:
        return self.w if self.w is not None else ca.SX.sym("w", 0)

    @property
    def W_box(self) -> Box:
        """W, or a 0-dimensional box when the model has no disturbance."""
        return self.W if self.W is not None else Box(np.zeros(0), np.zeros(0))

    # -------------------------------------------------------------- functions
    def _cached(self, key: Any, build: Callable[[], Any]) -> Any:
        if key not in self._cache:
            self._cache[key] = build()
        return self._cache[key]

    @property
    def function(self) -> ca.Function:
        """CasADi Function ``f(x, u, w) -> x_next`` (``w`` of size 0 without disturbance)."""
        return self._cached("function", lambda: ca.Function(
            f"{self.name}_f", [self.x, self.u, self._w_sym], [self.f],
            ["x", "u", "w"], ["x_next"]))

    @property
    def interval_function(self) -> ca.Function | ParamFunction:
        """The successor ``(x, u, w) -> x_next`` that interval evaluators are compiled from.

        For a model given by its expressions this is :attr:`function`. For a closed loop
        (:meth:`closed_loop`) it is a :class:`~casadi_cmpc.interval._derivative.ParamFunction`:
        the open-loop f composed with the law, every literal constant of both kept as an
        exact parameter. CasADi folds the constant subexpressions of ``f(x, law(x), w)`` in
        floating point (``exp(u + 0.1)`` with ``u = 0`` becomes ``fl(exp(0.1))``), so
        :attr:`f` and :attr:`function` of a closed loop hold a rounded model, fine for
        :meth:`step` but not for a proof; :meth:`inclusion`, :meth:`jacobian_inclusion` and
        the structure tests use this exact form. Constants that CasADi creates while
        composing (``a - a`` gives 0, then ``acos(0)`` is folded) are widened.
        """
        return self.interval_map("xuw")

    def interval_map(self, inputs: str = "xuw", joined: bool = False
                     ) -> ca.Function | ParamFunction:
        """The successor as a function of some of ``x``, ``u``, ``w``, for interval evaluators.

        Solvers that compile an interval evaluator of the successor should take it from
        here rather than build a Function from :attr:`f`, which of a closed loop is rounded
        (see :attr:`interval_function`).

        Parameters
        ----------
        inputs : str
            The inputs in order, e.g. ``"xuw"`` (default, see :attr:`interval_function`),
            ``"xw"`` or ``"x"``; a variable left out must have size 0 (``"x"`` for an
            autonomous model without disturbance).
        joined : bool
            One input, the chosen variables stacked (e.g. ``(n + l, 1)`` for ``"xw"``),
            instead of one input per variable.

        Returns
        -------
        casadi.Function or ParamFunction
            Inputs of shapes (n, 1), (m, 1), (l, 1) as chosen (or their stack), one output
            (n, 1). Literal constants are exact (of a closed loop: those of f and of the
            law; see :attr:`interval_function`). Accepted by
            :class:`~casadi_cmpc.interval.InclusionFunction`,
            :func:`~casadi_cmpc.interval.inclusion` and
            :class:`~casadi_cmpc.interval._derivative.JacobianInclusion`.
        """
        key = str(inputs).lower()
        if not key or any(k not in _WRT for k in key) or list(key) != sorted(
                set(key), key=_WRT.index):
            raise ValueError(f"inputs must list some of x, u, w in this order, each once; "
                             f"got '{inputs}'")
        size = {"x": self.n, "u": self.m, "w": self.l}
        left = [k for k in _WRT if k not in key and size[k] > 0]
        if left:
            raise ModelError(f"model '{self.name}' depends on {', '.join(left)}: the interval "
                             f"map must take {', '.join(left)} as input(s)")
        joined = bool(joined)
        if key == "xuw" and not joined and self._exact_f is None:
            return self.function

        def build() -> ca.Function | ParamFunction:
            sym = {"x": self.x, "u": self.u, "w": self._w_sym}
            ins = [sym[k] for k in key]
            names = list(key)
            if joined:
                ins, names = [ca.vertcat(*ins)], [key]
            name = f"{self.name}_{key}"
            if self._exact_f is None:
                return ca.Function(name, ins, [self.f], names, ["x_next"])
            assert self._exact_params is not None
            return exact_function(name, ins, [self._exact_f], *self._exact_params)

        return self._cached(("interval_map", key, joined), build)

    def jacobian_function(self, wrt: str) -> ca.Function:
        """CasADi Function ``(x, u, w) -> df/d<wrt>`` (dense, shape (n, d_wrt))."""
        wrt = _check_wrt(wrt)
        sym = {"x": self.x, "u": self.u, "w": self._w_sym}[wrt]

        def build() -> ca.Function:
            jac = ca.densify(ca.jacobian(self.f, sym))
            return ca.Function(f"{self.name}_jac_{wrt}", [self.x, self.u, self._w_sym],
                               [jac], ["x", "u", "w"], [f"df_d{wrt}"])

        return self._cached(("jacfun", wrt), build)

    def step(self, x: Any, u: Any = None, w: Any = None) -> np.ndarray:
        """Numeric successor state(s), evaluated by CasADi.

        Parameters
        ----------
        x : array_like, shape (N, n) or (n,)
        u : array_like, shape (N, m) or (m,); broadcast against x. Optional when m = 0.
        w : array_like, shape (N, l) or (l,); required when the model has w.

        Returns
        -------
        ndarray, shape (N, n) (or (n,) for a single unbatched state)
        """
        xs, batched = as_points(x, self.n, "x")
        us = self._arg_points(u, self.m, "u")
        ws = self._arg_points(w, self.l, "w")
        n_b = max(xs.shape[0], us.shape[0], ws.shape[0])
        for arr, nm in ((xs, "x"), (us, "u"), (ws, "w")):
            if arr.shape[0] not in (1, n_b):
                raise DimensionError(f"batch size of {nm} ({arr.shape[0]}) does not broadcast "
                                     f"to {n_b}")
        fun = self._cached(("map", n_b), lambda: self.function.map(n_b))
        out = np.asarray(fun(_cols(xs, n_b), _cols(us, n_b), _cols(ws, n_b))).T
        out = out.reshape(n_b, self.n)
        batched = batched or n_b > 1
        return out if batched else out[0]

    def _arg_points(self, v: Any, d: int, name: str) -> np.ndarray:
        if v is None:
            if d > 0:
                raise ModelError(f"{name} is required for this model (dimension {d})")
            return np.zeros((1, 0))
        return as_points(v, d, name)[0]

    # -------------------------------------------------------------- inclusion
    def inclusion(self, kind: str = "natural", *, backend: str = "auto"
                  ) -> Callable[..., np.ndarray]:
        """Batched interval inclusion function of one step.

        Parameters
        ----------
        kind : {"natural", "centered"}
            See :func:`casadi_cmpc.interval.inclusion`.
        backend : {"auto", "numpy", "scalar"}
            Evaluator of the boxes (Python float code for small batches, numpy for large
            ones with "auto"); see :func:`casadi_cmpc.interval.inclusion`.

        Returns
        -------
        callable ``F(X, U=None, W=None) -> ndarray (N, n, 2)``
            ``X``: boxes ``(N, n, 2)`` or ``(n, 2)`` or a Box; ``U``: ``(N, m, 2)`` (defaults
            to the model's U); ``W``: ``(N, l, 2)`` (defaults to the model's W). Batch sizes of
            1 broadcast. Every successor ``f(x, u, w)`` with x, u, w in the boxes lies inside.
        """
        kind = str(kind).lower()
        backend = str(backend).lower()
        F = self._cached(("inclusion", kind, backend),
                         lambda: inclusion(self.interval_function, kind, backend=backend))
        return _ModelInclusion(self, F)

    def jacobian_inclusion(self, wrt: str = "x",
                           kind: str = "natural") -> Callable[..., np.ndarray]:
        """Interval Jacobian of f with respect to ``x``, ``u`` or ``w`` over boxes.

        Parameters
        ----------
        wrt : {"x", "u", "w"}
        kind : {"natural"}
            The entries are natural inclusions of CasADi's symbolic derivatives.

        Returns
        -------
        callable ``J(X, U=None, W=None) -> ndarray (N, n, d_wrt, 2)``
            Interval matrices for the mean-value theorem (used by zonotope evolution, thesis
            Thm 4.3/4.4): for all points ``a``, ``b`` of a box that differ only in ``wrt``,
            ``f(b) - f(a)`` lies in ``J (b - a)`` row by row. Row ``i`` is ``[-inf, inf]`` on
            boxes where ``f_i`` may jump or leave its domain (floor, sign, comparisons,
            if_else, fmod, remainder, copysign, atan2's branch cut, poles such as ``1/x``
            across 0): CasADi's derivative of a jump (e.g. 0 for floor) says nothing there.
            Literal constants of f enter exactly (of a closed loop: those of f and of the
            law, see :attr:`interval_function`); constants created by differentiation are
            widened.
        """
        wrt = _check_wrt(wrt)
        kind = str(kind).lower()
        if kind != "natural":
            raise ValueError(f"jacobian_inclusion supports kind='natural' only; got '{kind}'")
        idx = _WRT.index(wrt)
        F = self._cached(("jac_inclusion", wrt),
                         lambda: JacobianInclusion(self.interval_function, wrt=idx))
        d = {"x": self.n, "u": self.m, "w": self.l}[wrt]

        def J(X: Any, U: Any = None, W: Any = None) -> np.ndarray:
            boxes, n_b = _model_boxes(self, X, U, W)
            out = F(boxes, n_b)
            return out.reshape(n_b, self.n, d, 2)

        return J

    # --------------------------------------------------------------- structure
    def _jac(self, wrt: str) -> ca.SX:
        """df/d<wrt> of :attr:`f` (numeric coefficients)."""
        sym = {"x": self.x, "u": self.u, "w": self._w_sym}[wrt]
        return self._cached(("jac_sx", wrt), lambda: ca.jacobian(self.f, sym))

    def _sjac(self, wrt: str) -> ca.SX:
        """df/d<wrt> for the structure tests: of the exact form of a closed loop (its
        parameters as symbols, so that no dependence is hidden by a folded constant), of
        :attr:`f` otherwise."""
        if self._exact_f is None:
            return self._jac(wrt)
        sym = {"x": self.x, "u": self.u, "w": self._w_sym}[wrt]
        return self._cached(("sjac_sx", wrt), lambda: ca.jacobian(self._exact_f, sym))

    def _jump_inputs(self) -> tuple[bool, bool, bool, tuple[int, ...]]:
        """Whether an operation of f that may jump or has a pole (floor, sign, comparisons,
        if_else, fmod, 1/x, ...) has its argument depending on x, u, w, and the states it
        depends on. CasADi differentiates such operations piecewise (a jump has derivative
        0), so a constant Jacobian does not make f affine when one of them depends on the
        variable: the structure tests below treat those variables as entering
        nonlinearly."""
        def build() -> tuple[bool, bool, bool, tuple[int, ...]]:
            try:
                pg = ParamGraph(self.interval_function)
            except UnsupportedOperationError:  # f calls a Function: assume the worst
                return self.n > 0, self.m > 0, self.l > 0, tuple(range(self.n))
            g = ca.vertcat(*[pg.guard_exprs]) if pg.guards else ca.SX(0, 1)
            if g.numel() == 0:
                return False, False, False, ()
            zx, zu, zw = pg.inputs
            dep = [z.numel() > 0 and ca.depends_on(g, z) for z in (zx, zu, zw)]
            states = tuple(j for j in range(self.n) if ca.depends_on(g, zx[j]))
            return dep[0], dep[1], dep[2], states
        return self._cached("jump_inputs", build)

    def _all_syms(self) -> list[ca.SX]:
        return [self.x, self.u] + ([self.w] if self.w is not None else [])

    def _depends(self, e: ca.SX, syms: list[ca.SX]) -> bool:
        return any(s.numel() > 0 and ca.depends_on(e, s) for s in syms)

    @property
    def is_affine_in_u(self) -> bool:
        """True when f is affine in u: df/du does not depend on u, and no operation that
        may jump (if_else, comparisons, floor, sign, ...) depends on u."""
        return self.m == 0 or not (ca.depends_on(self._sjac("u"), self.u)
                                   or self._jump_inputs()[1])

    @property
    def is_affine_in_w(self) -> bool:
        """True when f is affine in w: df/dw does not depend on w, and no operation that
        may jump (if_else, comparisons, floor, sign, ...) depends on w; True without w.
        Only then do the vertices of W bound the image ``f(x, u, W)``."""
        return self.w is None or not (ca.depends_on(self._sjac("w"), self.w)
                                      or self._jump_inputs()[2])

    @property
    def is_additive_in_w(self) -> bool:
        """True when w enters additively, f = g(x, u) + E w with a constant E; True without w."""
        return self.w is None or not (self._depends(self._sjac("w"), self._all_syms())
                                      or self._jump_inputs()[2])

    @property
    def is_linear(self) -> bool:
        """True when f is affine in (x, u, w) jointly: all Jacobians constant and no
        operation that may jump (if_else, comparisons, floor, sign, ...) in f."""
        return not (any(self._depends(self._sjac(k), self._all_syms())
                        for k in ("x", "u", "w") if k != "w" or self.w is not None)
                    or any(self._jump_inputs()[:3]))

    @property
    def nonlinear_states(self) -> tuple[int, ...]:
        """Indices j of the states that enter f nonlinearly (df/dx_j not constant).

        The other states form the affine state part of thesis §6.2:
        ``f = A x + g(x_NL, u, w)`` with ``A`` = :attr:`affine_state_matrix`.
        """
        def build() -> tuple[int, ...]:
            J = self._sjac("x")
            syms = self._all_syms()
            jump = self._jump_inputs()[3]
            return tuple(j for j in range(self.n)
                         if self._depends(J[:, j], syms) or j in jump)
        return self._cached("nonlinear_states", build)

    @property
    def linear_states(self) -> tuple[int, ...]:
        """Indices of the states that enter f only linearly (complement of nonlinear_states)."""
        nl = set(self.nonlinear_states)
        return tuple(j for j in range(self.n) if j not in nl)

    @property
    def has_affine_state_part(self) -> bool:
        """True when some, but not all, states enter only linearly (thesis §6.2)."""
        return 0 < len(self.nonlinear_states) < self.n

    @property
    def affine_state_matrix(self) -> np.ndarray:
        """A of shape (n, n): columns of the linear states (constant df/dx_j), zero elsewhere."""
        A = np.zeros((self.n, self.n))
        J = self._jac("x")
        for j in self.linear_states:
            A[:, j] = np.asarray(ca.DM(ca.evalf(J[:, j]))).reshape(-1)
        return A

    @property
    def has_affine_control_part(self) -> bool:
        """True when f = g(x, w) + B u with a constant B (thesis §6.3)."""
        if self._validation is not None:  # the true flow is not affine in u: no constant B
            return False
        return self.m > 0 and not self._depends(self._jac("u"), self._all_syms())

    @property
    def input_matrix(self) -> np.ndarray:
        """Constant B (n, m) of an affine control part; raises ModelError otherwise."""
        if not self.has_affine_control_part:
            raise ModelError(f"model '{self.name}' has no affine control part g(x, w) + B u")
        return np.asarray(ca.DM(ca.evalf(self._jac("u")))).reshape(self.n, self.m)

    def linear_enclosures(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Rigorous enclosures of ``(A, B, E, c)`` with ``f = A x + B u + E w + c``.

        Computed from the exact interval source of f (:meth:`interval_map`: the literals of
        f, and of a closed loop's law, are exact; nothing is folded in floating point): the
        interval Jacobians (constant for a linear model) and the natural inclusion of f at
        the origin, each at the thin point 0.

        Returns
        -------
        A, B, E, c : ndarray, shapes (n, n, 2), (n, m, 2), (n, l, 2), (n, 2)
            Interval entries ``[lo, hi]`` holding the exact coefficients.

        Raises
        ------
        ModelError
            The model is not linear.
        """
        if not self.is_linear:
            raise ModelError(f"model '{self.name}' is not linear in (x, u, w)")

        def build() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
            n, m, l = self.n, self.m, self.l
            args = (np.zeros((1, n, 2)), np.zeros((1, m, 2)) if m else None,
                    np.zeros((1, l, 2)) if l else None)

            def jac(wrt: str, d: int) -> np.ndarray:
                if d == 0:
                    return np.zeros((n, 0, 2))
                return np.asarray(self.jacobian_inclusion(wrt)(*args), dtype=float)[0]

            c = np.asarray(self.inclusion("natural")(*args), dtype=float)[0]
            return jac("x", n), jac("u", m), jac("w", l), c

        return self._cached("linear_enclosures", build)

    def linear_matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(A, B, E, c)`` with ``f = A x + B u + E w + c`` for a linear model.

        The midpoints of :meth:`linear_enclosures` (exact where those are thin, as for
        literal coefficients; otherwise within their width of the exact values, and
        computed from the exact graph, never from a folded one).

        Raises ModelError when the model is not linear.
        """
        A, B, E, c = self.linear_enclosures()

        def mid(M: np.ndarray) -> np.ndarray:
            with np.errstate(invalid="ignore", over="ignore"):
                v = 0.5 * M[..., 0] + 0.5 * M[..., 1]
            return np.where(M[..., 0] == M[..., 1], M[..., 0], v)

        return mid(A), mid(B), mid(E), mid(c)

    # ------------------------------------------------------------- closed loop
    def closed_loop(self, law: Any, name: str | None = None) -> Model:
        """The autonomous model ``x+ = f(x, law(x), w)``.

        Parameters
        ----------
        law : LinearLaw, array_like (m, n) or casadi.SX (m, 1)
            A :class:`~casadi_cmpc.LinearLaw` ``u = u_eq + K (x - x_eq)``, a bare gain
            ``K`` (``u = K x``) or an expression of ``x`` only (see
            :mod:`casadi_cmpc.control.law`).

        Returns
        -------
        Model
            With ``m = 0``; ``.law`` holds the law's expression in x and ``.input_box`` the
            open-loop U, so that input constraints ``law(X) ⊆ U`` can be checked. Its
            :attr:`f` is CasADi's substitution (constant subexpressions folded in floating
            point), used by :meth:`step`; its interval evaluators and structure tests use
            the exact composition :attr:`interval_function`.
        """
        if self.m == 0:
            raise ModelError(f"model '{self.name}' has no input to close the loop on")
        if isinstance(law, ca.MX):
            raise TypeError("give the law as casadi.SX in the model's x (or a gain matrix)")
        from .control.law import law_expr

        law_sx = law_expr(self, law)  # one convention: LinearLaw, gain (u = K x) or SX
        f_cl = ca.substitute(self.f, self.u, law_sx)
        names = set(self.state_names + self.disturbance_names)
        cl = Model(x=self.x, u=ca.SX.sym("u", 0), f=f_cl, w=self.w, X=self.X, U=None,
                   W=self.W, name=name or f"{self.name}_cl", state_names=self.state_names,
                   disturbance_names=self.disturbance_names or None, dt=self.dt,
                   units={k: v for k, v in self.units.items() if k in names})
        cl.law = law_sx
        cl.input_box = self.U
        cl._discretisation = self._discretisation
        cl._validation = self._validation
        try:
            cl._exact_f, params, values = self._exact_closed_loop(law_sx)
            cl._exact_params = (params, values)
        except UnsupportedOperationError:
            # f calls a Function (never_inline): no interval evaluator can be compiled from
            # it, and the structure tests take every variable as entering nonlinearly
            if self._validation is not None:  # pragma: no cover - from_ode builds SX only
                raise
        return cl

    def _exact_closed_loop(self, law_sx: ca.SX) -> tuple[ca.SX, ca.SX, np.ndarray]:
        """``f(x, law(x), w)`` with the literals of f and of the law as parameters.

        Returns the expression (in ``self.x``, ``self.w`` and the parameter symbols), the
        parameters (p, 1) and their values (p,). The law's own literals are parameters too,
        so that an operation of f on a constant law (``exp(u + 0.1)`` with ``u = 0``) stays
        symbolic instead of being folded; constants CasADi still creates by simplifying the
        composition are widened by :func:`~casadi_cmpc.interval._derivative.exact_function`.
        Raises UnsupportedOperationError when f or the law calls a Function.
        """
        # the exact form of a validated ODE model (interval-valued remainder), else f
        pf = ParamGraph(self.interval_function if self._exact_f is not None
                        else self.function)
        # dense law: a structural zero would enter f as the number 0 and fold
        pl = ParamGraph(ca.Function("law", [self.x], [ca.densify(law_sx)]))
        law_p = ca.Function("law_p", pl.inputs + [pl.params], pl.outputs).call(
            [self.x, pl.params])[0]
        f_p = ca.Function("f_p", pf.inputs + [pf.params], pf.outputs).call(
            [self.x, law_p, self._w_sym, pf.params])[0]
        bounds = np.concatenate([pf.bounds, pl.bounds])
        if (bounds[:, 0] < bounds[:, 1]).any():  # interval-valued or widened parameters
            return f_p, ca.vertcat(pf.params, pl.params), bounds
        return (f_p, ca.vertcat(pf.params, pl.params),
                np.concatenate([pf.values, pl.values]))

    def law_inclusion(self, kind: str = "natural") -> Callable[..., np.ndarray]:
        """For a closed-loop model: interval enclosure of the law, ``(N, n, 2) -> (N, m, 2)``."""
        if self.law is None:
            raise ModelError("law_inclusion needs a closed-loop model (see closed_loop)")
        fun = self._cached("law_fun", lambda: ca.Function(
            f"{self.name}_law", [self.x], [self.law], ["x"], ["u"]))
        F = self._cached(("law_inclusion", kind), lambda: InclusionFunction(fun, kind))
        return lambda X: F(as_boxes(X, self.n, "X"))[0]

    # ---------------------------------------------------------------- summary
    def equilibrium(self, u: Any = None, x0: Any = None, w: Any = None,
                    tol: float = 1e-12) -> np.ndarray:
        """The state ``x`` with ``f(x, u, w) = x`` near ``x0``, by Newton's method.

        Parameters
        ----------
        u : array_like (m,), optional
            The constant input (default: zeros).
        x0 : array_like (n,), optional
            Starting guess (default: the centre of X).
        w : array_like (l,), optional
            The disturbance (default: the centre of W).
        tol : float
            Required residual ``max |f(x, u, w) - x|``.

        Returns
        -------
        ndarray, shape (n,)

        Raises
        ------
        ModelError
            Newton's method did not reach ``tol`` from ``x0`` (try another guess).
        """
        uu = np.zeros(self.m) if u is None else as_points(u, self.m, "u")[0][0]
        xx = self.X.mid if x0 is None else as_points(x0, self.n, "x0")[0][0]
        ww = (self.W.mid if w is None else as_points(w, self.l, "w")[0][0]) if self.l \
            else np.zeros(0)
        z = ca.SX.sym("z", self.n)
        F = self.function(z, ca.DM(uu), ca.DM(ww)) - z
        J = ca.Function("newton", [z], [F, ca.jacobian(F, z)])
        x = np.array(xx, dtype=float)
        for _ in range(100):
            r, Jx = J(x)
            r = np.asarray(r, dtype=float).ravel()
            if np.abs(r).max() <= tol:
                return x
            try:
                dx = np.linalg.solve(np.asarray(Jx, dtype=float), -r)
            except np.linalg.LinAlgError:
                break
            x = x + dx
            if not np.isfinite(x).all():
                break
        raise ModelError(f"no equilibrium of '{self.name}' found from x0 = {list(xx)} with "
                         f"u = {list(uu)} (Newton's method did not converge to {tol:g})")

    def check_equilibrium(self, x: Any, u: Any, w: Any = None, names: str = "x_eq, u_eq",
                          rtol: float = 1e-9) -> None:
        """Raise ValueError unless ``f(x, u, w) = x`` (residual <= rtol (1 + |x|_inf)).

        ``names`` labels the pair in the message, e.g. ``"x_ref, u_ref"``; ``w`` defaults to
        the centre of W.
        """
        xe = np.asarray(x, dtype=float).reshape(self.n)
        ww = (self.W.mid if w is None else w) if self.l else None
        nxt = self.step(xe, u, ww)
        res = float(np.abs(nxt - xe).max())
        if not res <= rtol * (1.0 + float(np.abs(xe).max())):
            a, b = (s.strip() for s in names.split(","))
            raise ValueError(
                f"({names}) = ({xe.tolist()}, {np.asarray(u, dtype=float).tolist()}) is not "
                f"an equilibrium of '{self.name}': f({a}, {b}) - {a} = "
                f"{(nxt - xe).tolist()} (largest residual {res:.3g}); pass an equilibrium, "
                f"e.g. {a} = model.equilibrium({b}, x0=guess)")

    def summary(self) -> str:
        """A short multi-line description: sizes, names and units, boxes, sampling time,
        detected structure."""
        def named(names: tuple[str, ...]) -> str:
            return ", ".join(f"{v} [{self.units[v]}]" if v in self.units else v for v in names)

        lines = [
            f"Model '{self.name}': n = {self.n} states, m = {self.m} inputs, "
            f"l = {self.l} disturbances",
            f"  x = ({named(self.state_names)})",
            f"  X = {self.X!r}",
        ]
        if self.m:
            lines += [f"  u = ({named(self.input_names)})", f"  U = {self.U!r}"]
        else:
            lines.append("  U = (no input)")
        if self.W is not None:
            lines.append(f"  w = ({named(self.disturbance_names)})")
            lines.append(f"  W = {self.W!r}")
        lines.append(f"  sampling time dt = {self.dt:g} s" if self.dt is not None
                     else "  sampling time: not given (time in steps k)")
        lines.append(f"  map: {self.discretisation}")
        if self._validation is not None:
            v = self._validation
            lines.append(f"  validated domain (x, u, w) = {np.round(v['domain'], 6).tolist()};"
                         f" remainder width <= {v['remainder_width']:.3g}")
        if self.law is not None:
            lines.append(f"  closed loop with u = {self.law}")
        lines.append(f"  linear: {self.is_linear}; affine in u: {self.is_affine_in_u}; "
                     f"affine in w: {self.is_affine_in_w}; additive w: {self.is_additive_in_w}")
        lines.append(f"  nonlinear states: {list(self.nonlinear_states)}; affine control part:"
                     f" {self.has_affine_control_part}")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return f"Model('{self.name}', n={self.n}, m={self.m}, l={self.l})"

    @classmethod
    def from_ode(cls, x: Any, u: Any, rhs: Any, dt: float, method: str = "euler", w: Any = None,
                 X: Any = None, U: Any = None, W: Any = None, name: str = "model",
                 substeps: int = 1, *, time_unit: float | None = None, order: int = 4,
                 domain_margin: float = 0.05, **labels: Any) -> Model:
        """Discretise ``dx/dt = rhs(x, u, w)`` with a fixed step ``dt`` (time units of rhs).

        u is held constant over the sample (zero-order hold) and so is w (a disturbance
        constant over each sample).

        Parameters
        ----------
        x, u, w : casadi.SX, shapes (n, 1), (m, 1), (l, 1)
            Symbols of the state, input and (optional) disturbance.
        rhs : casadi.SX, shape (n, 1)
            The right-hand side, in state units per time unit.
        dt : float
            The sampling time in time units of ``rhs``.
        method : {"euler", "rk4", "taylor"}
            ``"euler"``/``"rk4"``: explicit Euler or classical Runge-Kutta 4 with
            ``substeps`` steps of ``dt / substeps`` per sample. No error bound: every
            certificate is about that map, not the ODE (see :attr:`discretisation`).
            ``"taylor"``: a *validated* sampled-data model. :attr:`f` (used by the
            optimisers, :meth:`step`, simulation and the C export of the controller) is
            the Taylor polynomial of order ``order`` of the flow in dt, built from the Lie
            derivatives ``F^[1] = rhs``, ``F^[i+1] = (dF^[i]/dx) rhs``; every interval
            evaluator (:meth:`inclusion`, :meth:`jacobian_inclusion`,
            :meth:`interval_map`, :meth:`interval_expr`, closed loops) encloses the true
            flow ``phi(dt; x, u, w)``: the Taylor polynomial plus a proven remainder
            ``rho + M (z - z_c)`` with interval ``rho``, ``M`` (Lagrange remainder over
            an a-priori enclosure of the trajectories, and of the variational equation for
            ``M``; see :mod:`casadi_cmpc._taylor`). The remainder holds on the validated
            domain: X, U, W each widened by ``domain_margin`` times its width; boxes that
            leave it give ``[-inf, inf]``. rhs must be smooth there: operations that jump
            or are not differentiable (floor, if_else, comparisons, sign, fmod, fabs,
            fmin, fmax, ...) are refused.
        X, U, W : Box or array_like
            The boxes of x, u, w (X and U required for ``"taylor"``).
        name : str
        substeps : int
            Steps per sample of euler/rk4 (must be 1 for ``"taylor"``).
        time_unit : float, optional
            Seconds per time unit of ``rhs`` (e.g. 60 for an ODE in minutes): the model's
            sampling time :attr:`dt` is then ``dt * time_unit`` seconds (default: unknown).
        order : int
            Taylor order k of ``"taylor"``, 1 to 12 (default 4).
        domain_margin : float
            Relative widening of X, U, W into the validated domain of ``"taylor"``.
        **labels
            ``state_names``, ``input_names``, ``disturbance_names``, ``units``: passed on to
            :class:`Model`.

        Raises
        ------
        ValueError
            Unknown method, bad dt, substeps, order.
        UnsupportedOperationError
            ``"taylor"`` with an rhs that may jump or is not smooth.
        ModelError
            ``"taylor"``: the ODE cannot be validated on the domain (no a-priori enclosure,
            rhs undefined or unbounded there).
        """
        method = str(method).lower()
        if method not in ("euler", "rk4", "taylor"):
            raise ValueError(f"unknown method '{method}'; valid methods: euler, rk4, taylor")
        if isinstance(dt, (bool, np.bool_)):
            raise TypeError("dt must be a number, not a bool")
        if not np.isfinite(dt) or dt <= 0:
            raise ValueError(f"dt must be a positive finite number; got {dt}")
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"substeps must be a positive integer; got {substeps}")
        if method == "taylor" and substeps != 1:
            raise ValueError("method='taylor' takes one step per sample (substeps=1); raise "
                             "the order instead, or lower dt")
        if u is None:
            u = ca.SX.sym("u", 0)
        x, u, w, rhs = _to_sx(x, u, w, rhs)
        if not isinstance(rhs, ca.SX):
            try:
                rhs = ca.SX(rhs)
            except Exception as exc:
                raise TypeError(f"rhs must be a casadi.SX expression; got {type(rhs).__name__}"
                                ) from exc
        if rhs.numel() != x.numel():
            raise DimensionError(
                f"rhs must have as many elements as x; expected {x.numel()} instead of "
                f"{rhs.numel()}")
        _check_free(rhs, [x, u, w], "rhs")
        rhs = ca.reshape(ca.densify(rhs), x.numel(), 1)
        bad = set(labels) - {"state_names", "input_names", "disturbance_names", "units"}
        if bad:
            raise TypeError(f"from_ode got unexpected keyword(s) {sorted(bad)}")
        if time_unit is not None and (not np.isfinite(time_unit) or time_unit <= 0):
            raise ValueError(f"time_unit must be a positive number of seconds; got {time_unit}")
        secs = None if time_unit is None else float(dt) * float(time_unit)
        if method == "taylor":
            return cls._from_ode_taylor(x, u, w, rhs, float(dt), X, U, W, name, secs,
                                        order, domain_margin, labels)
        args = [x, u] + ([w] if w is not None else [])
        g = ca.Function("rhs", args, [rhs])
        h = float(dt) / int(substeps)
        xk = x
        extra = [w] if w is not None else []
        for _ in range(int(substeps)):
            if method == "euler":
                xk = xk + h * g(xk, u, *extra)
            else:
                k1 = g(xk, u, *extra)
                k2 = g(xk + h / 2 * k1, u, *extra)
                k3 = g(xk + h / 2 * k2, u, *extra)
                k4 = g(xk + h * k3, u, *extra)
                xk = xk + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        model = cls(x=x, u=u, f=xk, w=w, X=X, U=U, W=W, name=name, dt=secs, **labels)
        model._discretisation = (f"the {'Euler' if method == 'euler' else 'RK4'} map of an "
                                 f"ODE (no error bound)")
        return model

    @classmethod
    def _from_ode_taylor(cls, x: ca.SX, u: ca.SX, w: ca.SX | None, rhs: ca.SX, dt: float,
                         X: Any, U: Any, W: Any, name: str, secs: float | None, order: Any,
                         margin: Any, labels: dict[str, Any]) -> Model:
        """The validated Taylor model of :meth:`from_ode` (method "taylor")."""
        from ._taylor import taylor_model

        n, m = x.numel(), u.numel()
        if X is None:
            raise ModelError("the state box X is required (e.g. X=cm.Box(lo, hi))")
        if U is None and m > 0:
            raise ModelError("the input box U is required (e.g. U=cm.Box(lo, hi))")
        if w is not None and W is None:
            raise ModelError("w is given but its range W is missing; pass W=cm.Box(lo, hi)")
        Xb = _as_model_box(X, n, "X")
        Ub = _as_model_box(U, m, "U") if U is not None else Box(np.zeros(0), np.zeros(0))
        Wb = _as_model_box(W, w.numel(), "W") if w is not None else None
        f_num, exact, params, bounds, info = taylor_model(
            x, u, w, rhs, dt, order, Xb, Ub, Wb, margin=margin)
        model = cls(x=x, u=u, f=f_num, w=w, X=Xb, U=Ub if m else None, W=Wb, name=name,
                    dt=secs, **labels)
        model._exact_f = exact
        model._exact_params = (params, bounds)
        model._validation = info
        model._discretisation = (
            f"the sampled-data ODE (validated Taylor, order {info['order']}, dt = {dt:g}"
            f"{'' if secs is None else f' (= {secs:g} s)'}, zero-order hold, w constant "
            "over the sample)")
        return model


def _check_wrt(wrt: str) -> str:
    wrt = str(wrt).lower()
    if wrt not in _WRT:
        raise ValueError(f"unknown variable '{wrt}'; valid: x, u, w")
    return wrt


def _cols(a: np.ndarray, n_b: int) -> np.ndarray:
    """(N or 1, d) -> (d, n_b) for a mapped CasADi call."""
    return np.broadcast_to(a, (n_b, a.shape[1])).T


class _ModelInclusion:
    """``F(X, U=None, W=None) -> (N, n, 2)`` wrapper around an InclusionFunction of f."""

    def __init__(self, model: Model, F: InclusionFunction) -> None:
        self.model = model
        self.F = F
        self.kind = F.kind
        self._defaults: tuple[Any, Any, np.ndarray, np.ndarray] | None = None

    def __call__(self, X: Any, U: Any = None, W: Any = None) -> np.ndarray:
        m = self.model
        if W is None or m.w is not None:
            # small batches of float arrays: the evaluator's own cheap checks
            d = self._defaults
            if d is None or d[0] is not m.U or d[1] is not m.W:
                d = self._defaults = (m.U, m.W, m.U.as_array(), m.W_box.as_array())
            out = self.F._call_small((X, d[2] if U is None else U, d[3] if W is None else W))
            if out is not None:
                return out[0]
        boxes, n_b = _model_boxes(m, X, U, W)
        return self.F.evaluate_unchecked(boxes, n_b)[0]

    def __repr__(self) -> str:
        return f"<{self.kind} inclusion of model '{self.model.name}'>"


def _model_boxes(m: Model, X: Any, U: Any, W: Any) -> tuple[list[np.ndarray], int]:
    """Validated ``(N_i, d_i, 2)`` boxes of x, u, w (U, W default to the model's) and the
    common batch size."""
    if U is None:
        U = m.U.as_array()
    if W is None:
        W = m.W_box.as_array()
    elif m.w is None:
        raise ModelError(f"model '{m.name}' has no disturbance; do not pass W")
    boxes = [as_boxes(X, m.n, "X"), as_boxes(U, m.m, "U"), as_boxes(W, m.l, "W")]
    ns = {b.shape[0] for b in boxes}
    n_b = max(ns)
    if len(ns - {1, n_b}) > 0:
        raise DimensionError(f"batch sizes of X, U, W do not broadcast: "
                             f"{[b.shape[0] for b in boxes]}")
    return boxes, n_b
