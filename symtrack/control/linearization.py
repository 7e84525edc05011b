"""Exact linearization at a trim point, as a named python-control ``StateSpace``.

A, B come from the model's ``jac_ode`` Function and C, D from ``jac_outputs`` (CasADi automatic
differentiation of the same expressions the simulator integrates; no finite differences).

States kept: by default every state except the position states x_m, y_m, yaw_rad. They are not
equilibrium coordinates: on a turn they keep changing, and on any trim the dynamics do not depend
on them (their columns of A are zero), so each would only add a pole at 0 that no input can
move. For straight running, ``path_frame=True`` keeps y_m and yaw_rad: along a straight
reference that is the trim's own x axis they are the lateral offset and the heading error, which
a path-tracking design needs (x_m is still dropped).

Outputs: the kept states (same names), then the model outputs (``model.output_names``) whose
names are not state names (the homogeneous terrain reports its sinkage states as outputs too).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..foundations.errors import ParameterError
from ..model import SystemModel
from .trim import POSITION_STATES, TrimPoint

if TYPE_CHECKING:
    import control

__all__ = ["INPUT_SCALE_N_M", "Linearization", "MODE_GROUPS", "SCHEMA_VERSION", "TYPICAL_SCALE", "bode_png",
           "controllability", "linearize", "load_npz", "modes", "npz_bytes", "report_markdown", "scale_by_name",
           "statespace_from_dict", "to_dict"]

SCHEMA_VERSION = 1

# Physical groups used to read the modes (a mode is named by the group that participates most).
MODE_GROUPS = (
    ("speed", ("u_m_s",)),
    ("lateral", ("v_m_s", "y_m")),
    ("yaw", ("yaw_rate_rad_s", "yaw_rad")),
    ("shear/sprocket", ("omega_left_rad_s", "omega_right_rad_s", "shear_left_m", "shear_right_m")),
    ("torque lag", ("torque_left_N_m", "torque_right_N_m")),
    ("lateral shear", ("lateral_shear_", "shear_twist_")),  # the "shear" law's lagged states
    ("sinkage cells", ("sinkage_",)),
)


@dataclass(frozen=True)
class Linearization:
    sys: control.StateSpace
    trim: TrimPoint
    state_names: tuple
    input_names: tuple
    output_names: tuple
    dropped_states: tuple
    x0: np.ndarray  # the trim values of the kept states
    u0: np.ndarray
    y0: np.ndarray

    def __repr__(self) -> str:
        """The sizes, the names (with their units) and the slowest modes; the matrices are ``A``,
        ``B``, ``C``, ``D`` (and ``sys``, the named python-control StateSpace)."""
        import numpy as np

        eig = np.linalg.eigvals(np.asarray(self.A, dtype=float)) if len(self.state_names) else np.array([])
        slow = sorted(eig, key=lambda z: (abs(z.real), abs(z.imag)))[:4]
        modes = ", ".join(f"{z.real:.4g}{z.imag:+.4g}j" if abs(z.imag) > 0 else f"{z.real:.4g}" for z in slow)
        trim = repr(self.trim).split("\n")[0].removeprefix("TrimPoint: ")
        dropped = f"; left out (no restoring dynamics): {', '.join(self.dropped_states)}" if self.dropped_states else ""
        return (f"Linearization at {trim}: {len(self.state_names)} states, {len(self.input_names)} inputs, "
                f"{len(self.output_names)} outputs{dropped}\n  states: {', '.join(self.state_names)}\n"
                f"  inputs: {', '.join(self.input_names)}\n  outputs: {', '.join(self.output_names)}\n"
                f"  slowest eigenvalues [1/s]: {modes or 'none'}")

    @property
    def A(self):
        return self.sys.A

    @property
    def B(self):
        return self.sys.B

    @property
    def C(self):
        return self.sys.C

    @property
    def D(self):
        return self.sys.D


def linearize(model: SystemModel, tp: TrimPoint, path_frame: bool = False) -> Linearization:
    """Exact Jacobians of ``model`` at the trim point ``tp`` as a named StateSpace."""
    if path_frame and tp.radius_m is not None:
        raise ParameterError("linearize path_frame = True needs straight running (radius None): "
                             "on a turn y_m and yaw_rad are not equilibrium coordinates")
    dropped = ("x_m",) if path_frame else POSITION_STATES
    names = list(model.state_names)
    keep = [i for i, n in enumerate(names) if n not in dropped]
    A, B = (np.array(M) for M in model.jac_ode(tp.x, tp.u, tp.p))
    Cy, Dy = (np.array(M) for M in model.jac_outputs(tp.x, tp.u, tp.p))
    y_all = np.array(model.outputs(tp.x, tp.u, tp.p)).ravel()
    out_extra = [i for i, n in enumerate(model.output_names) if n not in model.state_names]
    nk = len(keep)
    A, B = A[np.ix_(keep, keep)], B[keep, :]
    C = np.vstack([np.eye(nk), Cy[np.ix_(out_extra, keep)]])
    D = np.vstack([np.zeros((nk, B.shape[1])), Dy[out_extra, :]])
    state_names = tuple(names[i] for i in keep)
    output_names = state_names + tuple(model.output_names[i] for i in out_extra)
    import control  # python-control, imported on first use: its scipy.signal import takes seconds
    sys = control.ss(A, B, C, D, states=list(state_names), inputs=list(model.input_names),
                     outputs=list(output_names), name="symtrack_linear")
    y0 = np.concatenate([tp.x[keep], y_all[out_extra]])
    return Linearization(sys, tp, state_names, tuple(model.input_names), output_names, dropped,
                         tp.x[keep].copy(), tp.u.copy(), y0)


def _group(name: str) -> str:
    for group, keys in MODE_GROUPS:
        if any(name == k or (k.endswith("_") and name.startswith(k)) for k in keys):
            return group
    return "other"


def modes(lin: Linearization) -> list[dict]:
    """Eigenvalues with their physical reading.

    Each mode is classified by participation factors |v_i w_i| (right and left eigenvectors),
    which do not depend on the units of the states, summed over the groups of MODE_GROUPS.
    Complex pairs are reported once (positive imaginary part).
    """
    A = lin.A
    ev, V = np.linalg.eig(A)
    W = np.linalg.inv(V)  # rows: left eigenvectors, normalised so that W V = I
    out = []
    for k, lam in enumerate(ev):
        if lam.imag < -1e-9:
            continue
        part = np.abs(V[:, k] * W[k, :])
        part = part / part.sum() if part.sum() > 0 else part
        groups: dict[str, float] = {}
        for i, n in enumerate(lin.state_names):
            g = _group(n)
            groups[g] = groups.get(g, 0.0) + float(part[i])
        top = sorted(groups.items(), key=lambda kv: -kv[1])
        dom = [lin.state_names[i] for i in np.argsort(-part)[:3]]
        wn = abs(lam)
        entry = {
            "real_per_s": float(lam.real),
            "imag_rad_s": float(abs(lam.imag)),
            "natural_frequency_rad_s": float(wn),
            "damping_ratio": float(-lam.real / wn) if wn > 0 else None,
            "time_constant_s": float(-1 / lam.real) if lam.real < 0 else None,
            "reading": top[0][0],
            "group_participation": {g: round(v, 4) for g, v in top if v > 1e-3},
            "dominant_states": dom,
        }
        out.append(entry)
    out.sort(key=lambda e: e["natural_frequency_rad_s"])
    return out


# Typical magnitudes used to scale states before the controllability test (by name prefix).
TYPICAL_SCALE = (
    ("u_m_s", 1.0), ("v_m_s", 0.1), ("yaw_rate_rad_s", 0.1), ("y_m", 0.1), ("yaw_rad", 0.01),
    ("omega_", 1.0), ("lateral_shear_", 0.01), ("shear_twist_", 0.1), ("shear_", 0.01), ("torque_", 1000.0),
    ("sinkage_rate_", 0.01), ("sinkage_", 0.001),
)
INPUT_SCALE_N_M = 1000.0


def scale_by_name(name: str, table) -> float:
    """The typical magnitude of a named signal: the entry of ``table`` ((name or prefix ending in
    '_', value) pairs) that matches it first, else 1."""
    for key, val in table:
        if name == key or (key.endswith("_") and name.startswith(key)):
            return val
    return 1.0


def _typical(name: str) -> float:
    return scale_by_name(name, TYPICAL_SCALE)


def controllability(lin: Linearization, rtol: float = 1e-9) -> dict:
    """Controllability, mode by mode.

    States are scaled by typical magnitudes (TYPICAL_SCALE) and the inputs by 1 kN m; each
    eigenvector is normalised to unit length and the modal input gain |w_k^H B| (w_k: the left
    eigenvector, W V = I) is compared with the largest one: a mode whose relative gain is below
    rtol is reported uncontrollable (for distinct eigenvalues this is the PBH test). Identical
    terrain cells give repeated eigenvalues with more independent eigenvectors than inputs: some
    combinations of them are uncontrollable by any torque, which this test finds.
    The rank of the (scaled) controllability matrix is given for information only: for a stiff
    system it is numerically fragile.
    """
    A, B = lin.A, lin.B
    n = A.shape[0]
    s = np.array([_typical(nm) for nm in lin.state_names])
    As = A * s[None, :] / s[:, None]
    Bs = B * INPUT_SCALE_N_M / s[:, None]
    ev, V = np.linalg.eig(As)
    V = V / np.linalg.norm(V, axis=0, keepdims=True)
    W = np.linalg.inv(V)
    gains = np.linalg.norm(W @ Bs, axis=1)
    gmax = gains.max() if gains.size else 1.0
    per_mode = []
    for k, lam in enumerate(ev):
        if lam.imag < -1e-9:
            continue
        rel = float(gains[k] / gmax) if gmax > 0 else 0.0
        top = lin.state_names[int(np.argmax(np.abs(V[:, k])))]
        per_mode.append({"eigenvalue": [float(lam.real), float(lam.imag)], "relative_input_gain": rel,
                         "largest_state": top, "controllable": bool(rel > rtol)})
    import control  # python-control, imported on first use: its scipy.signal import takes seconds
    Wc = control.ctrb(As / max(np.linalg.norm(As, 2), 1e-12), Bs)
    sv = np.linalg.svd(Wc, compute_uv=False)
    rank = int(np.sum(sv > sv[0] * 1e-12))
    return {
        "n_states": n,
        "ctrb_rank_info": rank,
        "controllable": all(m["controllable"] for m in per_mode),
        "uncontrollable_modes": [m for m in per_mode if not m["controllable"]],
        "modes": per_mode,
        "rtol": rtol,
    }


def to_dict(lin: Linearization) -> dict:
    return {
        "schema_version": SCHEMA_VERSION,
        "trim": lin.trim.to_dict(),
        "state_names": list(lin.state_names),
        "input_names": list(lin.input_names),
        "output_names": list(lin.output_names),
        "dropped_states": list(lin.dropped_states),
        "x0": lin.x0.tolist(),
        "u0": lin.u0.tolist(),
        "y0": lin.y0.tolist(),
        "A": lin.A.tolist(),
        "B": lin.B.tolist(),
        "C": lin.C.tolist(),
        "D": lin.D.tolist(),
    }


def statespace_from_dict(d: dict) -> control.StateSpace:
    """Rebuild the named StateSpace from a linearization JSON (or npz) written by the CLI."""
    if int(d.get("schema_version", -1)) != SCHEMA_VERSION:
        raise ParameterError(f"linearization schema_version = {d.get('schema_version')!r}; "
                             f"this symtrack reads version {SCHEMA_VERSION}")
    import control  # python-control, imported on first use: its scipy.signal import takes seconds
    return control.ss(np.array(d["A"], float), np.array(d["B"], float), np.array(d["C"], float),
                      np.array(d["D"], float), states=list(d["state_names"]), inputs=list(d["input_names"]),
                      outputs=list(d["output_names"]), name="symtrack_linear")


def npz_bytes(lin: Linearization) -> bytes:
    import io

    buf = io.BytesIO()
    np.savez(buf, schema_version=np.array(SCHEMA_VERSION), A=lin.A, B=lin.B, C=lin.C, D=lin.D,
             x0=lin.x0, u0=lin.u0, y0=lin.y0, state_names=np.array(lin.state_names),
             input_names=np.array(lin.input_names), output_names=np.array(lin.output_names),
             dropped_states=np.array(lin.dropped_states))
    return buf.getvalue()


def load_npz(path) -> control.StateSpace:
    with np.load(path) as z:
        d = {k: z[k] for k in z.files}
    return statespace_from_dict({
        "schema_version": int(d["schema_version"]), "A": d["A"], "B": d["B"], "C": d["C"], "D": d["D"],
        "state_names": [str(s) for s in d["state_names"]], "input_names": [str(s) for s in d["input_names"]],
        "output_names": [str(s) for s in d["output_names"]]})


def bode_png(lin: Linearization, omega_rad_s=None) -> bytes:
    """Bode plots of the yaw-rate and speed responses to the two commanded torques."""
    import control  # python-control, imported on first use: its scipy.signal import takes seconds

    from ..reports.plots import plt, png_bytes  # matplotlib, imported when drawn (a second of its own)

    omega = np.logspace(-3, 3, 400) if omega_rad_s is None else omega_rad_s
    outs = ("u_m_s", "yaw_rate_rad_s")
    fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True)
    for j, oname in enumerate(outs):
        oi = lin.output_names.index(oname)
        for i, iname in enumerate(lin.input_names):
            sub = control.ss(lin.A, lin.B[:, [i]], lin.C[[oi], :], lin.D[[oi]][:, [i]])
            resp = control.frequency_response(sub, omega)
            mag = np.abs(np.asarray(resp.complex).ravel())
            ph = np.degrees(np.unwrap(np.angle(np.asarray(resp.complex).ravel())))
            ph -= 360.0 * np.round(ph[0] / 360.0)
            axes[0, j].loglog(omega, mag, label=iname)
            axes[1, j].semilogx(omega, ph, label=iname)
        unit = "m/s" if oname == "u_m_s" else "rad/s"
        axes[0, j].set_title(f"{oname} / torque command")
        axes[0, j].set_ylabel(f"|G| [{unit} per N m]")
        axes[1, j].set_ylabel("phase [deg]")
        axes[1, j].set_xlabel("frequency [rad/s]")
        for a in axes[:, j]:
            a.grid(True, which="both", alpha=0.4)
            a.legend(fontsize=8)
    tp = lin.trim
    where = "straight running" if tp.radius_m is None else f"a steady turn of radius {tp.radius_m:g} m"
    fig.suptitle(f"linearized at {where}, {tp.speed_m_s:g} m/s; torque commands "
                 f"{tp.u[0]:.0f} / {tp.u[1]:.0f} N m (left / right)")
    return png_bytes(fig)


def report_markdown(lin: Linearization, mode_list: list[dict], ctrb: dict) -> str:
    tp = lin.trim
    what = "straight running" if tp.radius_m is None else f"steady turn, R = {tp.radius_m:g} m"
    lines = [f"# Linearization at {what}, V = {tp.speed_m_s:g} m/s", "",
             f"States ({len(lin.state_names)}; dropped {', '.join(lin.dropped_states)}): "
             + ", ".join(lin.state_names), "",
             "| eigenvalue [1/s] | natural freq. [rad/s] | damping | reading | dominant states |",
             "|---|---|---|---|---|"]
    for m in mode_list:
        lam = f"{m['real_per_s']:.4g}" + (f" ± {m['imag_rad_s']:.4g}j" if m["imag_rad_s"] > 0 else "")
        z = "-" if m["damping_ratio"] is None else f"{m['damping_ratio']:.3f}"
        lines.append(f"| {lam} | {m['natural_frequency_rad_s']:.4g} | {z} | {m['reading']} | "
                     f"{', '.join(m['dominant_states'])} |")
    lines += ["", f"Controllable (modal test, relative gain > {ctrb['rtol']:g}): {ctrb['controllable']}; "
              f"rank of the scaled controllability matrix {ctrb['ctrb_rank_info']} of {ctrb['n_states']} "
              "(information only: fragile for a stiff system)"]
    for m in ctrb["uncontrollable_modes"]:
        a, b = m["eigenvalue"]
        lines.append(f"- uncontrollable: {a:.4g} ± {b:.4g}j (mostly {m['largest_state']}, relative input gain "
                     f"{m['relative_input_gain']:.1e})")
    return "\n".join(lines) + "\n"
