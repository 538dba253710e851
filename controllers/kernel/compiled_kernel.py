"""The compiled FHOCP kernel: generate, compile (gcc), cache and load it.

The single-shooting FHOCP (:mod:`controllers.ocp.nlp_single_shooting`) spends most of its time in
its derivatives: rollout, sensitivities, the Hessian of the Lagrangian and its eigenvalue
clipping. The kernel does the same mathematics in C (``controllers/kernel/*.c``) and either
runs the whole SQP itself (``sqp.c`` with the dense dual active-set QP of ``qp.c``;
:mod:`controllers.kernel.kernel_sqp`, the default) or is handed to casadi ``sqpmethod`` as
``external`` functions (``loop="casadi"``); either way the SQP runs without Python. It
agrees with the numpy callbacks to ~1e-14 (checked at load time, once per library and
process: :meth:`controllers.ocp.nlp_single_shooting.SingleShootingNLP.self_test`).

The C source is the fixed template (the interface ``kernel/gru_fhocp.h``, then ``memory.c``
… ``sqp.c``) preceded by a generated header holding the problem's dimensions (so that gcc
sees every loop bound) and the interface types shared with Python
(:mod:`controllers.kernel.kernel_abi`), and followed by the loader of its numbers (GRU
weights, Q, R, s, the reduced constraint rows ``D U_o``, the eigenvalue-clipping margin, the
input-rate weights when there are any: ``HAS_DU``, ``DW``; :func:`kernel_constants`), which
are declared in the source and read at load time (``loader.c``,
:mod:`controllers.kernel.constants`). So one compiled library serves every problem of the
same dimensions, and the exported controller (:mod:`controllers.kernel.controller_source`),
compiled from the same source with its numbers as data, computes exactly what this kernel
does. Each FHOCP gets its own workspace (:class:`~controllers.kernel.kernel_lib.Workspace`,
one C struct), so FHOCPs may solve concurrently from several threads. The library is cached
under a hash of the generated source, the compiler's identity and the flags, in the user's
cache folder (``~/.cache/gru-mpc/kernels`` on Linux; ``GRU_MPC_KERNEL_CACHE``); a problem's
numbers go into a copy of it named by their hash (a loaded library holds one problem's
numbers), made in milliseconds: a new model of known dimensions needs no compiler; new
dimensions compile on first use (2–4 s; ``make`` and ``cosim build-kernel`` build the
shipped model's). Files are written under temporary names and renamed, so processes
building one kernel at once agree.

Nothing here is needed for correctness: :func:`build` returns ``None`` (with the reason in
:data:`last_error`) when no C compiler is found, compilation fails or ``GRU_MPC_KERNEL=0`` is
set, and the FHOCP keeps the numpy callbacks (with a one-line warning).

Environment: ``GRU_MPC_KERNEL=0`` (off), ``GRU_MPC_KERNEL_CACHE`` (folder), ``CC`` (compiler),
``GRU_MPC_KERNEL_MODE=w|contract`` and ``GRU_MPC_KERNEL_BLAS=on|off`` (override the cost model).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import threading
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from controllers.gru import WEIGHT_LIMIT
from controllers.kernel.cbuild import compile_library, compiler_id, default_cache_dir, write_atomic
from controllers.kernel.constants import Constants
from controllers.kernel.kernel_abi import c_declarations
from controllers.kernel.kernel_lib import Kernel, Workspace
from controllers.ocp.solver_settings import FEAS_TOL

__all__ = ["GENERATOR_VERSION", "KERNEL_SELF_TEST_TOL", "Kernel", "KernelProblem", "Workspace",
           "build", "default_cache_dir", "for_fhocp", "generate_source", "kernel_constants",
           "last_error", "library_source", "loader_source", "variant_flags"]

#: Bump when the C template or the generated header changes meaning (part of the cache key).
GENERATOR_VERSION = "gru-fhocp-kernel-16"
#: The C template, joined in this order after the generated header: the interface
#: (``gru_fhocp.h``), the solver instance's memory, the mathematics bottom-up, the exported
#: API, the equilibrium for an output (tracking kernels), the QP and the SQP.
TEMPLATE_PARTS = tuple(Path(__file__).with_name(name) for name in (
    "gru_fhocp.h", "memory.c", "rollout.c", "steady_state.c", "soft.c", "derivatives.c",
    "hessian.c", "eigen_clip.c", "api.c", "equilibrium.c", "qp.c", "sqp.c"))
#: The loader of a library's numbers (:func:`loader_source`), joined after every use.
LOADER_C = Path(__file__).with_name("loader.c")
DEFAULT_CFLAGS = ("-O3", "-fPIC", "-shared", "-fvisibility=hidden", "-std=gnu99")
PREFIX_PLACEHOLDER = "@PFX@"

#: Largest relative difference between the compiled kernel and the numpy derivatives at the
#: load-time self-test (they agree to ~1e-14).
KERNEL_SELF_TEST_TOL = 1e-9

#: Reason of the last failed :func:`build` (None after a success).
last_error: str | None = None

#: Kernels loaded in this process, by library path (a library is loaded once per process).
_LOADED: dict[str, Kernel] = {}
#: Serialises building, loading and self-testing (the dictionaries here) between threads.
_LOCK = threading.RLock()
#: Builds that failed in this process, by cache key: not retried (the reason is kept).
_FAILED: dict[str, str] = {}


@dataclass(frozen=True)
class KernelProblem:
    """What a kernel is generated from, described once: the FHOCP's model, horizon, weights
    and constraint rows (:meth:`of` an FHOCP; a future exported controller compiles the
    same).

    Attributes
    ----------
    params : mapping of arrays
        GRU weights (``eq:gru``).
    N : int
        Horizon.
    Q, R : arrays
        Stage weights (n×n, m×m).
    DUo : (q, n) array
        The reduced output-constraint rows ``D U_o`` of the NLP.
    s : float
        Terminal weight.
    clip : float, optional
        Eigenvalue-clipping margin of the SQP's Hessian (none: no clipping).
    LUo : (q, n) array, optional
        The full output-constraint rows ``L U_o`` of the answer check (``assess``).
    du_weight : (m,) array, optional
        Input-rate weights (:mod:`controllers.ocp.input_rate`; none or all zero: no
        input-rate term, ``HAS_DU 0``).
    offset_weight : (p,) array, optional
        The tracking law's offset weights T (:mod:`controllers.laws.tracking.reference`: the
        artificial steady state, ``HAS_ASS 1``; none: the paper's law).
    control_horizon : int, optional
        ``M < N`` (tracking only): the free inputs ``u_0 … u_{M−1}``, the tail held at
        ``u_s`` (``NM``; none: ``N``).
    soft : (float, float), optional
        The softened rows' weights ``(ρ, ρ_2)`` (:mod:`controllers.ocp.soft`: ``SOFT 1``, ``SLT``
        the answer check's tolerance :data:`~controllers.ocp.solver_settings.FEAS_TOL`; one slack
        per row of ``L`` and the terminal set's, ``DUo`` the unpaired ``LUo``); none: the hard
        problem.
    bias_shift : bool
        The biases move with measured disturbances (``HAS_SHIFT``: the per-thread shift of
        :meth:`~controllers.kernel.kernel_lib.Kernel.set_bias_shift`, ``rollout.c`` gk_db);
        without them the kernel has no thread-local state at all.
    move : bool
        The move limit's rows ``eq:move-constraint`` end ``g`` (``HAS_MOVE``:
        :class:`controllers.ocp.input_rate.MoveRows`, their bounds the caller's).
    """

    params: Mapping[str, np.ndarray]
    N: int
    Q: np.ndarray
    R: np.ndarray
    DUo: np.ndarray
    s: float
    clip: float | None = None
    LUo: np.ndarray | None = None
    du_weight: np.ndarray | None = None
    offset_weight: np.ndarray | None = None
    control_horizon: int | None = None
    soft: tuple[float, float] | None = None
    bias_shift: bool = False
    move: bool = False

    @property
    def has_du(self) -> bool:
        """The input-rate term is compiled (``HAS_DU``): some ``du_weight`` is not 0."""
        return self.du_weight is not None and bool(np.any(np.asarray(self.du_weight) != 0.0))

    @classmethod
    def of(cls, fhocp: Any) -> KernelProblem:
        """The kernel problem of an :class:`~controllers.ocp.fhocp.FHOCP`, with its law's
        terms (:meth:`controllers.ocp.reference.Reference.kernel_terms`: the tracking law's offset
        weights and control horizon)."""
        return cls(fhocp.params, fhocp.N, fhocp.Q, fhocp.R, fhocp.DUo, fhocp.s,
                   fhocp.sqp_options.get("hessian_eigen_clip"), fhocp.LUo, fhocp.du_weight,
                   **fhocp.reference.kernel_terms(),
                   soft=None if fhocp.slacks is None else (fhocp.soft_design.rho,
                                                           fhocp.soft_design.rho2),
                   bias_shift=bool(getattr(fhocp, "bias_shift", False)),
                   move=fhocp.move is not None)


def generate_source(problem: KernelProblem, constants: Constants | None = None) -> str:
    """The C source of ``problem``'s kernel up to ``sqp.c`` (symbol prefix left as
    ``@PFX@``): its dimensions defined, its numbers ``constants`` (default:
    :func:`kernel_constants`) declared and not defined (:func:`library_source` adds their
    loader)."""
    params, N, offset_weight = problem.params, int(problem.N), problem.offset_weight
    n, m = np.shape(params["W_z"])
    q = np.atleast_2d(np.asarray(problem.DUo, dtype=float)).shape[0]
    M = N if problem.control_horizon is None else int(problem.control_horizon)
    if M < 1 or M > N or (M < N and offset_weight is None):
        raise ValueError(f"control horizon {M} must be in 1..N = {N}, below N only "
                         "with the artificial steady state")
    constants = kernel_constants(problem) if constants is None else constants
    n_l = 0 if problem.LUo is None else np.atleast_2d(np.asarray(problem.LUo)).shape[0]
    Q = np.asarray(problem.Q, dtype=float).reshape(n, n)
    hdr = [f"/* generated by controllers.kernel.compiled_kernel ({GENERATOR_VERSION}); "
           "do not edit */\n",
           f"#define NX {n}\n#define NU {m}\n#define NH {N}\n#define NM {M}\n"
           f"#define NQ {q}\n"
           f"#define NY {np.shape(params['U_o'])[0]}\n#define NL {n_l}\n",
           f"#define HAS_DU {int(problem.has_du)}\n"
           f"#define HAS_ASS {int(offset_weight is not None)}\n"
           f"#define HAS_SHIFT {int(problem.bias_shift)}\n"
           f"#define SOFT {int(problem.soft is not None)}\n"
           f"#define HAS_MOVE {int(problem.move)}\n",
           f"#define PFX(name) {PREFIX_PLACEHOLDER}##name\n", c_declarations(),
           constants.declarations(),
           f"#define QDIAG {int(np.count_nonzero(Q - np.diag(np.diag(Q))) == 0)}\n"]
    return "".join(hdr) + "\n" + "".join(p.read_text() for p in TEMPLATE_PARTS)


def loader_source(constants: Constants) -> str:
    """The table of ``constants`` and their loader (``loader.c``: ``PFX(load_data)``), to
    join after every use of them."""
    return constants.table() + LOADER_C.read_text()


def library_source(problem: KernelProblem, constants: Constants | None = None) -> str:
    """The complete C source of ``problem``'s kernel library: :func:`generate_source` and the
    loader of its numbers ``constants`` (default: :func:`kernel_constants`); the same for
    every problem of the same dimensions."""
    constants = kernel_constants(problem) if constants is None else constants
    return generate_source(problem, constants) + loader_source(constants)


def kernel_constants(problem: KernelProblem) -> Constants:
    """The numbers of ``problem``'s kernel: the GRU's weights (``eq:gru``, with transposed
    and stacked copies for the mat-vecs), the output map, the stage and terminal weights, the
    constraint rows and the clipping margin."""
    P = {k: np.asarray(v, dtype=float) for k, v in problem.params.items()}
    n, m = P["W_z"].shape
    DUo = np.atleast_2d(np.asarray(problem.DUo, dtype=float))
    if DUo.shape[1] != n:
        raise ValueError("DUo must be q x n")
    LUo = (np.zeros((0, n)) if problem.LUo is None
           else np.atleast_2d(np.asarray(problem.LUo, dtype=float)))
    if LUo.shape[1] != n:
        raise ValueError("LUo must be q x n")
    c = Constants()
    w = (-WEIGHT_LIMIT, WEIGHT_LIMIT)
    for key in ("W_z", "W_r", "W_h", "U_z", "U_r", "U_h", "b_z", "b_r", "b_h"):
        c.array(key.replace("_", "").upper(), P[key], limits=w)
    for key in ("U_z", "U_r", "U_h"):   # transposed copies for column-oriented mat-vecs
        c.array(key.replace("_", "").upper() + "T", P[key].T, limits=w)
    c.array("UO", P["U_o"], limits=w)
    c.array("BO", P["b_o"], limits=w)
    c.array("JZ", np.hstack([P["U_z"], P["W_z"]]), limits=w)
    c.array("JR", np.hstack([P["U_r"], P["W_r"]]), limits=w)
    c.array("QW", np.asarray(problem.Q, dtype=float).reshape(n, n))
    c.array("RW", np.asarray(problem.R, dtype=float).reshape(m, m))
    c.array("DUO", DUo if DUo.shape[0] else np.zeros((1, n)))
    c.array("LUO", LUo if LUo.shape[0] else np.zeros((1, n)))
    c.scalar("SW", float(problem.s))
    if problem.has_du:
        c.array("DW", np.asarray(problem.du_weight, dtype=float).reshape(m))
    if problem.offset_weight is not None:
        c.array("TW", np.asarray(problem.offset_weight, dtype=float).reshape(-1))
    c.scalar("CLIP", -1.0 if problem.clip is None else float(problem.clip))
    if problem.soft is not None:
        c.scalar("SLW", float(problem.soft[0]))
        c.scalar("SLQ", float(problem.soft[1]))
        c.scalar("SLT", FEAS_TOL)
    return c


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
#: eigenvalue clipping when N m >= this, else the own eigenpairs below the margin (Householder,
#: QL without vectors, inverse iteration; eigen_clip.c). On Hessian-like matrices with 3
#: eigenvalues below the margin (the paper scenario clips ~2.4 per decomposition),
#: ``benchmarks/bench_mpc.py --clip`` (2026-12-05): own / dsyevr 33 / 39 µs at N m = 30, 87 /
#: 92 at 48, 135 / 119 at 60, 744 / 470 at 120 (the own full tred2/tql2 before: 45, 134,
#: 248, 1,563 µs). Not below 80: at N m = 30 (the paper's problem)
#: the closed loop showed no difference (p99 9.8 / 10.0 ms over 4 alternating runs), nor at
#: the tracking law's default N m = 40 on the four-tank (median step 0.79 ms either way), and
#: a kernel without OpenBLAS gives the same answers on every CPU (OpenBLAS picks its kernels
#: by CPU), to the bit those of the exported controller (:mod:`controllers.kernel.
#: controller_source`, which cannot carry OpenBLAS).
LAPACK_EIG_MIN_NU = 80



def choose_mode(n: int, m: int, N: int, M: int | None = None) -> str:
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
    N = 30 and 60, 1.7× slower at N = 15). Env ``GRU_MPC_KERNEL_MODE`` overrides. With a
    control horizon ``M < N`` (the inputs' columns stop growing after stage M) the
    contracted mode is not available."""
    M = N if M is None else M
    env = os.environ.get("GRU_MPC_KERNEL_MODE", "auto")
    if env in ("w", "backward") or (env == "contract" and M == N):
        return env
    v = n + m
    cw = cc = cb = 0.0
    for i in range(N):
        K = min(i, M + 1) * m   # S_i's input columns: i m, at most (M + 1) m
        Kc = K + m
        cw += n * n * v + 2 * n * n * K + 1.5 * n * v * v + 0.5 * n * K * K
        cc += 3 * n * n * Kc + 2.5 * n * Kc * Kc + n * n * K
        cb += 2 * n * n * v + n * n * K + 2.5 * n * v * v + m * n * K
    if M < N:
        return "backward" if cb < cw else "w"
    if cb < min(cw, cc):
        return "backward"
    return "contract" if cc < 0.8 * cw else "w"


def variant_flags(problem: KernelProblem, flags: tuple[str, ...] = DEFAULT_CFLAGS,
                  blas: bool = True) -> tuple[tuple[str, ...], list[str]]:
    """``(flags, libs)`` of ``problem``'s kernel: ``flags`` with its build-time variant
    (:func:`choose_mode`) and, when ``blas`` and casadi's OpenBLAS is there, LAPACK's
    eigenvalue clipping for large problems (and ``GRU_MPC_KERNEL_BLAS=on``: the BLAS
    products), with the libraries to link; ``blas=False``: a self-contained library (the
    exported controller)."""
    params, N, clip = problem.params, problem.N, problem.clip
    control_horizon = problem.control_horizon
    libs: list[str] = []
    n_states = np.shape(params["W_z"])[0]
    openblas = casadi_openblas() if blas else None
    # BLAS (casadi's OpenBLAS) for the big products only when GRU_MPC_KERNEL_BLAS=on: the
    # register-blocked products beat it at every size measured (Jacobian / Hessian at
    # N = 15, blocked against BLAS: 164 / 445 and 325 / 475 µs at n = 40, 469 / 1364 and
    # 564 / 861 µs at n = 80, 1.87 / 4.21 and 1.58 / 2.08 ms at n = 160; closed-loop median
    # at n = 80: 2.3–2.9 against 4.5–4.6 ms)
    use_blas = openblas is not None and os.environ.get("GRU_MPC_KERNEL_BLAS") == "on"
    mode = choose_mode(n_states, np.shape(params["W_z"])[1], int(N),
                       None if control_horizon is None else int(control_horizon))
    if mode != "w":
        flags = (*flags, {"contract": "-DGK_CONTRACT", "backward": "-DGK_BACKWARD"}[mode])
    lapack_eig = (openblas is not None and clip is not None
                  and int(control_horizon or N) * np.shape(params["W_z"])[1] >= LAPACK_EIG_MIN_NU
                  and os.environ.get("GRU_MPC_KERNEL_BLAS", "auto") != "off")
    if use_blas:
        flags = (*flags, "-DGK_BLAS")
    if lapack_eig:
        flags = (*flags, "-DGK_LAPACK_EIG")
    if (use_blas or lapack_eig) and openblas is not None:
        libs = [f"-L{openblas.parent}", f"-l:{openblas.name}", f"-Wl,-rpath,{openblas.parent}"]
    return flags, libs


def build(problem: KernelProblem, *, cache_dir: str | Path | None = None,
          cc: str | None = None, cflags: tuple[str, ...] | None = None,
          verbose: bool = False) -> Kernel | None:
    """Compiled kernel for ``problem``, from the cache or freshly built; ``None`` on failure
    (reason in :data:`last_error`). Thread-safe; the library is shared by every caller in
    the process (each takes its own :meth:`Kernel.workspace`)."""
    global last_error
    with _LOCK:
        k, last_error = _build(problem, cache_dir, cc, cflags, verbose)
        return k


def _build(problem: KernelProblem, cache_dir: str | Path | None, cc: str | None,
           cflags: tuple[str, ...] | None, verbose: bool
           ) -> tuple[Kernel | None, str | None]:
    """:func:`build`: ``(kernel, None)`` or ``(None, reason)``; the caller holds ``_LOCK``."""
    if os.environ.get("GRU_MPC_KERNEL", "1") == "0":
        return None, "disabled by GRU_MPC_KERNEL=0"
    cc = cc or os.environ.get("CC") or "gcc"
    if shutil.which(cc) is None:
        return None, f"no C compiler {cc!r} on PATH"
    flags, libs = variant_flags(problem, tuple(cflags) if cflags is not None else DEFAULT_CFLAGS)
    try:
        constants = kernel_constants(problem)
        src, data = library_source(problem, constants), constants.data()
    except ValueError as exc:
        return None, f"cannot generate the kernel: {exc}"
    key = hashlib.sha256("\0".join([GENERATOR_VERSION, compiler_id(cc), " ".join(flags),
                                    " ".join(libs), src]).encode()).hexdigest()[:16]
    if key in _FAILED:
        return None, _FAILED[key]
    prefix = f"gk{key}_"
    cdir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    shared = cdir / f"gk{key}.so"
    # the problem's own copy of the library: a loaded library holds one problem's numbers
    so = cdir / f"gk{key}-{hashlib.sha256(data).hexdigest()[:12]}.so"
    loaded = _LOADED.get(str(so))
    if loaded is not None and so.exists():
        return loaded, None
    if not shared.exists():
        reason = _compile(src.replace(PREFIX_PLACEHOLDER, prefix), cdir, key, cc, flags, libs)
        if reason is not None:
            _FAILED[key] = reason
            return None, reason
        meta = {"flags": list(flags), "libs": libs, "compiler": compiler_id(cc),
                "generator": GENERATOR_VERSION, "n": int(np.shape(problem.params["W_z"])[0]),
                "N": int(problem.N)}
        with contextlib.suppress(OSError):   # informative only
            write_atomic(cdir / f"gk{key}.json", json.dumps(meta, indent=1).encode())
        if verbose:
            print(f"compiled FHOCP kernel: built {shared}")
    try:
        if not so.exists():
            write_atomic(so, shared.read_bytes())
        k = Kernel(so, prefix, data)
    except (OSError, ValueError) as exc:
        return None, f"cannot load {so}: {exc}"
    k.flags = flags
    _LOADED[str(so)] = k
    return k, None


def _compile(csource: str, cdir: Path, key: str, cc: str, flags: tuple[str, ...],
             libs: list[str]) -> str | None:
    """Compile ``csource`` into ``cdir/gk<key>.so`` (:func:`controllers.kernel.cbuild.
    compile_library`); the reason when it fails."""
    reason = compile_library(csource, cdir, f"gk{key}", cc, flags, libs)
    return None if reason is None else reason.replace("build failed:", "kernel build failed:")


#: Kernel libraries checked against the numpy callbacks in this process, with the outcome.
_SELF_TESTED: dict[str, float] = {}
#: Reasons already warned about (one warning per reason and process).
_WARNED: set[str] = set()


def for_fhocp(fhocp: Any) -> tuple[Workspace | None, str | None]:
    """A workspace of the compiled kernel of a :class:`controllers.ocp.fhocp.FHOCP`'s problem
    (its own C state: FHOCPs may solve concurrently), the library self-tested against the
    numpy derivatives once per library and process: ``(workspace, None)``, or
    ``(None, reason)`` with a one-line warning (once per reason and process) when it cannot
    be built or disagrees with them. Thread-safe. The calling thread's bias shift
    (:meth:`~controllers.kernel.kernel_lib.Kernel.set_bias_shift`) is reset to zero."""
    import warnings

    problem = KernelProblem.of(fhocp)
    with _LOCK:
        k, reason = _build(problem, None, None, None, False)
        if k is not None:
            # the nominal biases on this thread (a measured disturbance's shift,
            # FHOCP.shift_biases, is given again at every control step)
            k.set_bias_shift(np.zeros(3 * k.n))
            key = str(k.path)
            if key not in _SELF_TESTED:
                _SELF_TESTED[key] = fhocp.numpy_nlp().self_test(k.workspace(), problem.clip)
            if _SELF_TESTED[key] > KERNEL_SELF_TEST_TOL:
                reason = (f"self-test against the numpy derivatives failed (relative "
                          f"difference {_SELF_TESTED[key]:.1e})")
                k = None
        warn = k is None and reason not in _WARNED
        if warn:
            _WARNED.add(str(reason))
    if warn:
        warnings.warn(f"compiled FHOCP kernel unavailable ({reason}); using the numpy "
                      "derivatives", RuntimeWarning, stacklevel=3)
    return (k.workspace(), None) if k is not None else (None, reason)
