"""The compiled FHOCP kernel: generate, compile (gcc), cache and load it.

The single-shooting FHOCP (:mod:`controllers.nlp_single_shooting`) spends most of its time in
its derivatives: rollout, sensitivities, the Hessian of the Lagrangian and its eigenvalue
clipping. The kernel does the same mathematics in C (``controllers/kernel/*.c``) and either
runs the whole SQP itself (``6_sqp.c`` with the dense dual active-set QP of ``5_qp.c``;
:mod:`controllers.kernel_sqp`, the default) or is handed to casadi ``sqpmethod`` as
``external`` functions (``loop="casadi"``); either way the SQP runs without Python. It
agrees with the numpy callbacks to ~1e-14 (checked at load time, once per library and
process: :meth:`controllers.nlp_single_shooting.SingleShootingNLP.self_test`).

The C source is the fixed template (``kernel/1_rollout.c`` … ``6_sqp.c``) preceded by a
generated header holding the
problem's dimensions and constants (GRU weights, Q, R, s, the reduced constraint rows
``D U_o``, the eigenvalue-clipping margin) as ``static const`` arrays, so that gcc sees every
loop bound. The shared library is cached under a hash of the generated source, the
compiler's identity and the flags, in ``~/.cache/gru-mpc/kernels`` (``GRU_MPC_KERNEL_CACHE``):
a second controller for the same model and problem loads it in milliseconds; a changed model,
horizon, weight or generator gives a new hash (a user's model gets its own kernel on first
use, 2–4 s; ``make`` and ``cosim build-kernel`` build the shipped model's).

Nothing here is needed for correctness: :func:`build` returns ``None`` (with the reason in
:data:`last_error`) when no C compiler is found, compilation fails or ``GRU_MPC_KERNEL=0`` is
set, and the FHOCP keeps the numpy callbacks (with a one-line warning).

Environment: ``GRU_MPC_KERNEL=0`` (off), ``GRU_MPC_KERNEL_CACHE`` (folder), ``CC`` (compiler),
``GRU_MPC_KERNEL_MODE=w|contract`` and ``GRU_MPC_KERNEL_BLAS=on|off`` (override the cost model).
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import json
import os
import shutil
import subprocess
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["GENERATOR_VERSION", "KERNEL_SELF_TEST_TOL", "Kernel", "build", "default_cache_dir",
           "for_fhocp", "generate_source", "last_error"]

#: Bump when the C template or the generated header changes meaning (part of the cache key).
GENERATOR_VERSION = "gru-fhocp-kernel-3"
#: The C template, concatenated in this order after the generated header.
TEMPLATE_PARTS = tuple(Path(__file__).with_name("kernel") / name for name in (
    "1_rollout.c", "2_derivatives.c", "3_eigen_clip.c", "4_api.c", "5_qp.c", "6_sqp.c"))
DEFAULT_CFLAGS = ("-O3", "-fPIC", "-shared", "-fvisibility=hidden", "-std=gnu99")
PREFIX_PLACEHOLDER = "@PFX@"

#: Largest relative difference between the compiled kernel and the numpy derivatives at the
#: load-time self-test (they agree to ~1e-14).
KERNEL_SELF_TEST_TOL = 1e-9

#: Reason of the last failed :func:`build` (None after a success).
last_error: str | None = None

#: Kernels loaded in this process, by library path (a library is loaded once per process).
_LOADED: dict[str, Kernel] = {}
#: Builds that failed in this process, by cache key: not retried (the reason is kept).
_FAILED: dict[str, str] = {}


def default_cache_dir() -> Path:
    """``GRU_MPC_KERNEL_CACHE``, else ``$XDG_CACHE_HOME/gru-mpc/kernels`` (``~/.cache``)."""
    env = os.environ.get("GRU_MPC_KERNEL_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "gru-mpc" / "kernels"


def _c_array(name: str, a: np.ndarray) -> str:
    a = np.ascontiguousarray(np.asarray(a, dtype=float)).ravel()
    if not np.all(np.isfinite(a)):
        raise ValueError(f"non-finite entries in {name}")
    body = ", ".join(repr(float(v)) for v in a)   # repr: shortest exact round trip
    return f"static const double {name}[{max(a.size, 1)}] = {{{body or '0.0'}}};\n"


def generate_source(params: Mapping[str, np.ndarray], N: int, Q: np.ndarray, R: np.ndarray,
                    DUo: np.ndarray, s: float, clip: float | None,
                    LUo: np.ndarray | None = None) -> str:
    """The complete C source (symbol prefix left as ``@PFX@``); ``LUo`` (q×n): the full
    output-constraint rows ``L U_o`` of the answer check (``assess``), none when omitted."""
    P = {k: np.asarray(v, dtype=float) for k, v in params.items()}
    n, m = P["W_z"].shape
    DUo = np.atleast_2d(np.asarray(DUo, dtype=float))
    q = DUo.shape[0]
    if DUo.shape[1] != n:
        raise ValueError("DUo must be q x n")
    Q = np.asarray(Q, dtype=float).reshape(n, n)
    R = np.asarray(R, dtype=float).reshape(m, m)
    LUo = np.zeros((0, n)) if LUo is None else np.atleast_2d(np.asarray(LUo, dtype=float))
    if LUo.shape[1] != n:
        raise ValueError("LUo must be q x n")
    hdr = [f"/* generated by controllers.compiled_kernel ({GENERATOR_VERSION}); do not edit */\n",
           f"#define NX {n}\n#define NU {m}\n#define NH {int(N)}\n#define NQ {q}\n"
           f"#define NY {P['U_o'].shape[0]}\n#define NL {LUo.shape[0]}\n",
           f"#define PFX(name) {PREFIX_PLACEHOLDER}##name\n"]
    for key in ("W_z", "W_r", "W_h", "U_z", "U_r", "U_h", "b_z", "b_r", "b_h"):
        hdr.append(_c_array(key.replace("_", "").upper(), P[key]))
    for key in ("U_z", "U_r", "U_h"):   # transposed copies for column-oriented mat-vecs
        hdr.append(_c_array(key.replace("_", "").upper() + "T", P[key].T))
    hdr.append(_c_array("UO", P["U_o"]))
    hdr.append(_c_array("BO", P["b_o"]))
    hdr.append(_c_array("JZ", np.hstack([P["U_z"], P["W_z"]])))
    hdr.append(_c_array("JR", np.hstack([P["U_r"], P["W_r"]])))
    hdr.append(_c_array("QW", Q))
    hdr.append(_c_array("RW", R))
    hdr.append(_c_array("DUO", DUo if q else np.zeros((1, n))))
    hdr.append(_c_array("LUO", LUo if LUo.shape[0] else np.zeros((1, n))))
    hdr.append(f"static const double SW = {float(s)!r};\n")
    hdr.append(f"#define QDIAG {int(np.count_nonzero(Q - np.diag(np.diag(Q))) == 0)}\n")
    hdr.append(f"static const double CLIP = {(-1.0 if clip is None else float(clip))!r};\n")
    return "".join(hdr) + "\n" + "".join(p.read_text() for p in TEMPLATE_PARTS)


def casadi_openblas() -> Path | None:
    """casadi's bundled OpenBLAS (Linux wheels), used for the O(n^3) products of large
    models; None when absent."""
    try:
        import casadi
    except ImportError:
        return None
    p = Path(casadi.__file__).parent / "libcasadi-tp-openblas.so.0"
    return p if p.exists() else None


#: LAPACK dsyevr (casadi's OpenBLAS; only the eigenpairs below the clipping margin) for the
#: eigenvalue clipping when N m >= this, else the own tred2/tql2 (all pairs). On Hessian-like
#: matrices with 3 eigenvalues below the margin (the paper scenario clips ~2.4 per
#: decomposition), ``benchmarks/bench_mpc.py --clip``: own / dsyevr 83 / 61 µs at N m = 30,
#: 366 / 273 µs at 60, 2.6 / 0.86 ms at 120. Not below 40: at N m = 30 (the paper's problem)
#: the closed loop showed no difference (p99 9.8 / 10.0 ms over 4 alternating runs), and
#: the default kernel then needs no OpenBLAS.
LAPACK_EIG_MIN_NU = 40



def choose_mode(n: int, m: int, N: int) -> str:
    """The kernel's variant for a GRU of ``n`` states, ``m`` inputs and horizon ``N``, by a
    flop model of one Jacobian + Hessian evaluation:

    - ``"w"``: explicit stage Jacobians and stage Hessians ``W_i``, then ``Σ Z_iᵀ W_i Z_i``;
      O(N n³ + N² n² m + N³ n m²);
    - ``"contract"``: everything contracted with ``Z_i = [S_i; E_i]`` first;
      O(N² n² m + N³ n m²) with larger constants, for large n;
    - ``"backward"``: the W-mode stage blocks condensed backward from the end of the horizon
      (a Riccati-like recursion for the Hessian); O(N n³ + N² n m²), for long horizons.

    Contracted mode is taken when its count is below 0.8× W-mode's, backward mode when its
    count is below both others (at n = 20, m = 2 its Hessian measured 1.8–2.0× faster at
    N = 30 and 60, 1.7× slower at N = 15). Env ``GRU_MPC_KERNEL_MODE`` overrides."""
    env = os.environ.get("GRU_MPC_KERNEL_MODE", "auto")
    if env in ("w", "contract", "backward"):
        return env
    v = n + m
    cw = cc = cb = 0.0
    for i in range(N):
        K = i * m
        Kc = K + m
        cw += n * n * v + 2 * n * n * K + 1.5 * n * v * v + 0.5 * n * K * K
        cc += 3 * n * n * Kc + 2.5 * n * Kc * Kc + n * n * K
        cb += 2 * n * n * v + n * n * K + 2.5 * n * v * v + m * n * K
    if cb < min(cw, cc):
        return "backward"
    return "contract" if cc < 0.8 * cw else "w"


@functools.cache
def _compiler_id(cc: str) -> str:
    try:
        out = subprocess.run([cc, "--version"], capture_output=True, text=True, timeout=30)
        return out.stdout.splitlines()[0] if out.stdout else cc
    except (OSError, subprocess.SubprocessError):
        return cc


class Kernel:
    """A loaded kernel library: ctypes handle, dimensions and casadi external functions."""

    def __init__(self, path: Path, prefix: str) -> None:
        self.path = Path(path)
        self.prefix = prefix
        self.lib = ctypes.CDLL(str(self.path))
        dims = (ctypes.c_long * 7)()
        self._fn("dims")(dims)
        self.n, self.m, self.N, self.q, self.nw, self.ng, self.npar = list(dims)
        vp, cd, ci = ctypes.c_void_p, ctypes.c_double, ctypes.c_int
        self.nl = int(self._fn("n_assess_rows")())
        self._externals: dict[str, Any] = {}
        # persistent argument and result buffers, their addresses taken once (numpy's
        # ``.ctypes.data`` costs microseconds per call)
        n, m, N = self.n, self.m, self.N
        self._buf = {name: np.zeros(shape) for name, shape in (
            ("x0", n), ("u", (N, m)), ("w", self.nw), ("p", self.npar), ("xb", n),
            ("ub", m), ("dz", n), ("dr", n), ("bnd", (N, max(self.nl, 1))), ("out", 7),
            ("x", (N + 1, n)), ("uc", (N, m)), ("xn", n), ("y", m), ("xe", n), ("ue", m))}
        self._addr = {name: int(a.ctypes.data) for name, a in self._buf.items()}
        self._c: dict[str, Any] = {}
        for name, args, rest in (
                ("simulate", [vp] * 3, None), ("xtraj", [vp] * 3, None),
                ("gru_step", [vp] * 5, None), ("assess", [vp] * 5 + [cd, vp, vp], None),
                ("assess_w", [vp, vp, vp, cd, vp, vp, vp], None)):
            f = self._fn(name)
            f.argtypes, f.restype = args, rest
            self._c[name] = f
        f = self._fn("sqp")
        f.argtypes, f.restype = [vp] * 12, ci
        self._c["sqp"] = f
        if hasattr(self.lib, prefix + "eq_newton"):
            f = self._fn("eq_newton")
            f.argtypes, f.restype = [vp, vp, vp, ci, cd, vp, vp], ci
            self._c["eq_newton"] = f

    def _fn(self, name: str) -> Any:
        return getattr(self.lib, self.prefix + name)

    def external(self, name: str) -> Any:
        """casadi Function ``name`` in {"fg", "jac_fg", "hess_l", "hess_raw"} (loaded once)."""
        if name not in self._externals:
            import casadi as ca

            self._externals[name] = ca.external(self.prefix + name, str(self.path))
        return self._externals[name]

    def simulate(self, x0: np.ndarray, u: np.ndarray) -> np.ndarray:
        """States ``x_0 … x_N`` (N+1, n) from ``x0`` under ``u`` (N, m); no cache involved."""
        b, a = self._buf, self._addr
        b["x0"][:] = x0
        b["u"][:] = u
        self._c["simulate"](a["x0"], a["u"], a["x"])
        return b["x"].copy()

    def xtraj(self, w: np.ndarray, p: np.ndarray) -> np.ndarray:
        """The kernel's trajectory at ``(w, p)`` (its cached rollout when it matches)."""
        b, a = self._buf, self._addr
        b["w"][:] = np.ravel(w)
        b["p"][:] = np.ravel(p)
        self._c["xtraj"](a["w"], a["p"], a["x"])
        return b["x"].copy()

    def gru_step(self, x: np.ndarray, u: np.ndarray, dz: np.ndarray, dr: np.ndarray
                 ) -> np.ndarray:
        """One step of ``eq:gru`` with extra gate inputs (``eq:observer``), as
        :func:`controllers.gru.step`; a new array."""
        b, a = self._buf, self._addr
        b["x0"][:] = x
        b["ub"][:] = u
        b["dz"][:] = dz
        b["dr"][:] = dr
        self._c["gru_step"](a["x0"], a["ub"], a["dz"], a["dr"], a["xn"])
        return b["xn"].copy()

    def assess(self, x0: np.ndarray, u: np.ndarray, x_bar: np.ndarray, u_bar: np.ndarray,
               bounds: np.ndarray, alpha: float) -> tuple[np.ndarray, np.ndarray]:
        """The check of an input sequence in one call: states ``x_0 … x_N`` from ``x0`` under
        ``u`` (N, m) and ``[cost, max row violation at i = 0, max row violation at i ≥ 1,
        max |u|, ‖x_N − x̄‖∞, active constraints]`` (as ``FHOCP.cost`` with ``t = ‖x_N −
        x̄‖∞`` and ``FHOCP._residuals``; ``bounds``: the tightened bounds, N×q)."""
        b, a = self._buf, self._addr
        b["x0"][:] = x0
        b["u"][:] = u
        b["xb"][:] = x_bar
        b["ub"][:] = u_bar
        b["bnd"][:, :self.nl] = bounds
        self._c["assess"](a["x0"], a["u"], a["xb"], a["ub"], a["bnd"], float(alpha), a["x"],
                          a["out"])
        return b["x"].copy(), b["out"][:6].copy()

    def assess_w(self, w: np.ndarray, p: np.ndarray, bounds: np.ndarray, alpha: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`assess` of the solver's answer ``w`` at ``p = (x̂, x̄, ū)``: ``(u, x, out)``
        with ``u = clip(w_u, −1, 1)`` and ``out[6]`` the defect ``max |x_solver − x|``
        against the solver's trajectory at ``(w, p)``."""
        b, a = self._buf, self._addr
        b["w"][:] = w
        b["p"][:] = p
        b["bnd"][:, :self.nl] = bounds
        self._c["assess_w"](a["w"], a["p"], a["bnd"], float(alpha), a["uc"], a["x"], a["out"])
        return b["uc"].copy(), b["x"].copy(), b["out"].copy()

    def eq_newton(self, y: np.ndarray, x0: np.ndarray, u0: np.ndarray, max_iter: int = 20,
                  tol: float = 1e-11) -> tuple[np.ndarray, np.ndarray] | None:
        """:func:`controllers.equilibrium.equilibrium_newton`, compiled: ``(x, u)`` or
        ``None``."""
        b, a = self._buf, self._addr
        b["y"][:] = y
        b["x0"][:] = x0
        b["ub"][:] = u0
        rc = self._c["eq_newton"](a["y"], a["x0"], a["ub"], int(max_iter), float(tol),
                                  a["xe"], a["ue"])
        uo = b["ue"]
        if rc != 0 or max(abs(uo)) > 1.0:
            return None
        return b["xe"].copy(), uo.copy()

    def sqp_call(self, arrays: Mapping[str, np.ndarray]) -> Any:
        """A function running the kernel's SQP (``6_sqp.c``) on these persistent arrays:
        ``p, lbx, ubx, lbg, ubg, w, lam_x, lam_g, g, f, opt, info`` (float64, contiguous;
        ``w``, ``lam_x``, ``lam_g`` hold the initial guess and receive the answer). Their
        addresses are taken once: calling it costs ~1 µs besides the solve."""
        names = ("p", "lbx", "ubx", "lbg", "ubg", "w", "lam_x", "lam_g", "g", "f", "opt",
                 "info")
        for name in names:
            a = arrays[name]
            if a.dtype != np.float64 or not a.flags.c_contiguous:
                raise ValueError(f"sqp array {name!r} must be contiguous float64")
        keep = {name: arrays[name] for name in names}   # alive as long as the function
        addr = [int(keep[name].ctypes.data) for name in names]
        fn = self._c["sqp"]
        return lambda _keep=keep: fn(*addr)

    def qp(self, H: np.ndarray, g: np.ndarray, A: np.ndarray, lbx: np.ndarray,
           ubx: np.ndarray, lba: np.ndarray, uba: np.ndarray
           ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, int]:
        """The kernel's QP (``5_qp.c``) on one problem of its dimensions (H: nw×nw, A:
        ng×nw; infinite bounds allowed): ``(status, d, lam_x, lam_a, working-set changes)``,
        status 0 optimal, 1 infeasible, 2 change limit, 3 H not positive definite. A test
        hook: the SQP calls the QP inside the kernel."""
        def arr(a: np.ndarray, order: str = "C") -> np.ndarray:
            return np.clip(np.array(a, dtype=float, order=order), -1e301, 1e301)
        args = [arr(H), arr(g), arr(A, "F"), arr(lbx), arr(ubx), arr(lba), arr(uba)]
        d, lx, la = np.zeros(self.nw), np.zeros(self.nw), np.zeros(self.ng)
        changes = ctypes.c_int(0)
        P = ctypes.POINTER(ctypes.c_double)
        status = self._fn("qp")(*(a.ctypes.data_as(P) for a in (*args, d, lx, la)),
                                ctypes.byref(changes))
        return int(status), d, lx, la, int(changes.value)

    def counters(self) -> dict[str, int]:
        c = (ctypes.c_long * 4)()
        self._fn("counters")(c)
        return {"hess_calls": c[0], "eig": c[1], "clipped": c[2], "eigenvalues_clipped": c[3]}

    def invalidate(self) -> None:
        self._fn("invalidate")()


def build(params: Mapping[str, np.ndarray], N: int, Q: np.ndarray, R: np.ndarray,
          DUo: np.ndarray, s: float, clip: float | None, *, LUo: np.ndarray | None = None,
          cache_dir: str | Path | None = None, cc: str | None = None,
          cflags: tuple[str, ...] | None = None, verbose: bool = False) -> Kernel | None:
    """Compiled kernel for this problem, from the cache or freshly built; ``None`` on failure
    (reason in :data:`last_error`). ``LUo``: the full output-constraint rows ``L U_o`` of
    :meth:`Kernel.assess` (``FHOCP.LUo``)."""
    global last_error
    last_error = None
    if os.environ.get("GRU_MPC_KERNEL", "1") == "0":
        last_error = "disabled by GRU_MPC_KERNEL=0"
        return None
    cc = cc or os.environ.get("CC") or "gcc"
    if shutil.which(cc) is None:
        last_error = f"no C compiler {cc!r} on PATH"
        return None
    flags = tuple(cflags) if cflags is not None else DEFAULT_CFLAGS
    libs: list[str] = []
    n_states = np.shape(params["W_z"])[0]
    blas = casadi_openblas()
    # BLAS (casadi's OpenBLAS) for the big products only when GRU_MPC_KERNEL_BLAS=on: the
    # register-blocked products beat it at every size measured (Jacobian / Hessian at
    # N = 15, blocked against BLAS: 164 / 445 and 325 / 475 µs at n = 40, 469 / 1364 and
    # 564 / 861 µs at n = 80, 1.87 / 4.21 and 1.58 / 2.08 ms at n = 160; closed-loop median
    # at n = 80: 2.3–2.9 against 4.5–4.6 ms)
    use_blas = blas is not None and os.environ.get("GRU_MPC_KERNEL_BLAS") == "on"
    mode = choose_mode(n_states, np.shape(params["W_z"])[1], int(N))
    if mode != "w":
        flags = (*flags, {"contract": "-DGK_CONTRACT", "backward": "-DGK_BACKWARD"}[mode])
    lapack_eig = (blas is not None and clip is not None
                  and int(N) * np.shape(params["W_z"])[1] >= LAPACK_EIG_MIN_NU
                  and os.environ.get("GRU_MPC_KERNEL_BLAS", "auto") != "off")
    if use_blas and blas is not None:
        flags = (*flags, "-DGK_BLAS")
    if lapack_eig:
        flags = (*flags, "-DGK_LAPACK_EIG")
    if (use_blas or lapack_eig) and blas is not None:
        libs = [f"-L{blas.parent}", f"-l:{blas.name}", f"-Wl,-rpath,{blas.parent}"]
    try:
        src = generate_source(params, N, Q, R, DUo, s, clip, LUo)
    except ValueError as exc:
        last_error = f"cannot generate the kernel: {exc}"
        return None
    key = hashlib.sha256("\0".join([GENERATOR_VERSION, _compiler_id(cc), " ".join(flags),
                                    " ".join(libs), src]).encode()).hexdigest()[:16]
    if key in _FAILED:
        last_error = _FAILED[key]
        return None
    prefix = f"gk{key}_"
    cdir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    so = cdir / f"gk{key}.so"
    loaded = _LOADED.get(str(so))
    if loaded is not None and so.exists():
        return loaded
    if not so.exists():
        try:
            cdir.mkdir(parents=True, exist_ok=True)
            csrc = cdir / f"gk{key}.c"
            csrc.write_text(src.replace(PREFIX_PLACEHOLDER, prefix))
            fd, tmp = tempfile.mkstemp(suffix=".so", dir=cdir)
            os.close(fd)
            cmd = [cc, *flags, "-o", tmp, str(csrc), *libs, "-lm"]
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
            if res.returncode != 0:
                os.unlink(tmp)
                first = (res.stderr.strip().splitlines() or ["no message"])[0]
                last_error = _FAILED[key] = f"{cc} failed on {csrc}: {first[:300]}"
                return None
            os.replace(tmp, so)      # atomic: concurrent builders agree on the content
            meta = {"flags": list(flags), "libs": libs, "compiler": _compiler_id(cc),
                    "generator": GENERATOR_VERSION, "n": int(n_states), "N": int(N)}
            (cdir / f"gk{key}.json").write_text(json.dumps(meta, indent=1))
            if verbose:
                print(f"compiled FHOCP kernel: built {so}")
        except (OSError, subprocess.SubprocessError) as exc:
            last_error = _FAILED[key] = f"kernel build failed: {exc}"
            return None
    try:
        k = Kernel(so, prefix)
        k.flags = flags
        _LOADED[str(so)] = k
        return k
    except OSError as exc:
        last_error = _FAILED[key] = f"cannot load {so}: {exc}"
        return None


#: Kernel libraries checked against the numpy callbacks in this process, with the outcome.
_SELF_TESTED: dict[str, float] = {}
#: Reasons already warned about (one warning per reason and process).
_WARNED: set[str] = set()


def for_fhocp(fhocp: Any) -> tuple[Kernel | None, str | None]:
    """The compiled kernel of a :class:`controllers.fhocp.FHOCP`'s problem, self-tested
    against the numpy derivatives (once per library and process): ``(kernel, None)``, or
    ``(None, reason)`` with a one-line warning (once per reason and process) when it cannot
    be built or disagrees with them."""
    import warnings

    from controllers.nlp_single_shooting import SingleShootingNLP

    clip = fhocp.sqp_options.get("hessian_eigen_clip")
    k = build(fhocp.params, fhocp.N, fhocp.Q, fhocp.R, fhocp.DUo, fhocp.s, clip,
              LUo=fhocp.LUo)
    reason = last_error
    if k is not None:
        key = str(k.path)
        if key not in _SELF_TESTED:
            _SELF_TESTED[key] = SingleShootingNLP(fhocp, None).self_test(k, clip)
        if _SELF_TESTED[key] > KERNEL_SELF_TEST_TOL:
            reason = (f"self-test against the numpy derivatives failed (relative difference "
                      f"{_SELF_TESTED[key]:.1e})")
            k = None
    if k is None and reason not in _WARNED:
        _WARNED.add(str(reason))
        warnings.warn(f"compiled FHOCP kernel unavailable ({reason}); using the numpy "
                      "derivatives", RuntimeWarning, stacklevel=3)
    return k, (None if k is not None else reason)
