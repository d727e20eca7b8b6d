"""Serial manipulators: :class:`Robot`, a chain of revolute and prismatic joints read from a URDF, with the
rigid-body dynamics of its bodies' inertial parameters (the core's recursive Newton–Euler, its regressor, the mass
matrix, gravity and forward dynamics), as Pinocchio computes them. SI units: rad, m, kg, N·m, N."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

import numpy as np

from .. import _checks, _core
from .._errors import DataError


#: The numeric attributes of a URDF's elements, by element: each a number, or three (xyz, rpy).
_NUMBERS = {"mass": ("value",), "inertia": ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"), "origin": ("xyz", "rpy"),
            "axis": ("xyz",), "limit": ("lower", "upper", "effort", "velocity"), "dynamics": ("damping", "friction")}


def _unreadable(text: str) -> Optional[str]:
    """Where a URDF that the parser refuses is unreadable, in words (the XML's line and column where it breaks off
    or goes wrong, or the first numeric attribute that is not a number, with its link or joint), or None."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        line, col = e.position
        return (f"its XML is not well formed at line {line}, column {col} ({str(e).split(':')[0]}: a file cut short "
                "or a tag left open?)")
    for owner in list(root.iter("link")) + list(root.iter("joint")):
        for el in owner.iter():
            for key in _NUMBERS.get(el.tag, ()):
                value = el.get(key)
                if value is None:
                    continue
                try:
                    [float(x) for x in value.split()]
                except ValueError:
                    return (f"{owner.tag} {owner.get('name')}'s <{el.tag} {key}=\"{value}\">: not a number; give "
                            f"{'three numbers' if key in ('xyz', 'rpy') else 'a number'}")
    return None


class Robot:
    """A serial chain of actuated joints under gravity, (0, 0, −9.81) m/s² in the URDF's world frame.

    Built by :meth:`from_urdf`: the URDF's revolute (and continuous) and prismatic joints from its root link down,
    fixed joints merged into the body before them; ``joints`` picks the actuated ones by name, in the chain's order
    (the others are locked at zero). By default every movable joint, or, when the tree splits at the end of a chain
    into shorter branches (a gripper's fingers), the chain with the branches locked (``locked_joints``). Each body carries the 10 standard inertial parameters of the URDF
    (``inertial_params``, named ``m_<joint>``, ``mx_<joint>``, … ``Izz_<joint>``: mass, first moments m·c and the
    inertia about the joint frame's origin, in the joint's frame: Pinocchio's dynamic parameters).

    The dynamics take arrays of shape (n,) for one state or (N, n) for N states and return the same leading shape:
    :meth:`rnea` (inverse dynamics), :meth:`aba` (forward dynamics), :meth:`gravity`, :meth:`mass_matrix`,
    :meth:`regressor` (``rnea(q, v, a) = regressor(q, v, a) @ inertial_params``). Rotor inertia and friction are
    not part of these (they belong to the drive: see the identification)."""

    def __init__(self, core: "_core.Robot", urdf: str, source: Optional[str] = None):
        self._core = core
        #: The URDF text the robot was read from (kept with saved results, so that they carry their robot).
        self.urdf = urdf
        #: Where it was read from (a path), if from a file.
        self.source = source

    @classmethod
    def from_urdf(cls, path, joints: Optional[Sequence[str]] = None) -> "Robot":
        """The robot of the URDF file at ``path``; ``joints``: the actuated joints' names (default: every revolute,
        continuous and prismatic joint of the chain)."""
        from ..formats._io import check_input

        shown = check_input(path, "URDF file")
        try:
            with open(shown, encoding="utf-8") as f:
                text = f.read()
        except UnicodeDecodeError as e:
            raise DataError(f"{shown}: not a UTF-8 text file, so not a URDF ({e.reason})") from None
        except OSError as e:
            raise DataError(f"{shown}: cannot be read ({e.strerror or e})") from None
        return cls.from_urdf_string(text, joints, source=os.fspath(shown))

    @classmethod
    def from_urdf_string(cls, text: str, joints: Optional[Sequence[str]] = None,
                         source: Optional[str] = None) -> "Robot":
        """The robot of a URDF document given as text."""
        if not isinstance(text, str):
            raise DataError(f"the URDF must be text, got {type(text).__name__}")
        if joints is not None:
            if isinstance(joints, str) or not all(isinstance(j, str) for j in joints):
                raise DataError("joints must be a list of joint names")
            joints = list(joints)
        try:
            core = _core.Robot.from_urdf(text, joints)
        except DataError as e:
            where = _unreadable(text) if str(e).startswith("not a URDF robot description:") else None
            e = DataError(f"not a URDF robot description: {where}") if where else e
            if source is None:
                raise e from None
            raise DataError(f"{source}: {e}") from None
        return cls(core, text, source)

    # ------------------------------------------------------------------------------------------------ description

    @property
    def name(self) -> str:
        return self._core.name

    @property
    def joint_names(self) -> List[str]:
        return list(self._core.joint_names)

    @property
    def joint_kinds(self) -> List[str]:
        """"revolute" or "prismatic", per joint."""
        return list(self._core.joint_kinds)

    @property
    def locked_joints(self) -> List[str]:
        """The URDF's movable joints that are not actuated (locked at zero, their bodies merged into the body before
        them): those left out of ``joints``, or by default the short branches at the end of the chain (a gripper's
        fingers)."""
        return list(self._core.locked_joints)

    @property
    def ndof(self) -> int:
        return self._core.ndof

    @property
    def gravity_vector(self) -> np.ndarray:
        """The gravity acceleration in the world frame (m/s²)."""
        return np.array(self._core.gravity_vector, dtype=float)

    @property
    def param_names(self) -> List[str]:
        return list(self._core.param_names)

    @property
    def inertial_params(self) -> np.ndarray:
        """The bodies' inertial parameters (10 per joint, in the order of :attr:`param_names`)."""
        return np.asarray(self._core.inertial_params)

    @property
    def limits(self) -> List[Tuple[float, float, float, float]]:
        """Per joint (lower, upper, velocity, effort) from the URDF, infinite where it gives none."""
        return list(self._core.limits)

    def with_inertial_params(self, params) -> "Robot":
        """The same chain with other inertial parameters (as :attr:`inertial_params`)."""
        p = _checks.real_array("params", params, (1,))
        bad = np.flatnonzero(~np.isfinite(p))
        if bad.size:
            raise DataError(f"inertial parameter {bad[0]} is {p[bad[0]]}: every inertial parameter must be finite")
        return Robot(self._core.with_inertial_params(np.ascontiguousarray(p)), self.urdf, self.source)

    def __repr__(self) -> str:
        locked = f", locked={self.locked_joints}" if self.locked_joints else ""
        return f"Robot({self.name!r}, joints={self.joint_names}{locked})"

    # ------------------------------------------------------------------------------------------------ dynamics

    def _states(self, **arrays) -> Tuple[List[np.ndarray], bool]:
        """The arrays as (N, n) float64, and whether they were given as one state (n,)."""
        n, out, single = self.ndof, [], None
        for name, x in arrays.items():
            a = _checks.real_array(name, x, (1, 2))
            if a.shape[-1] != n:
                raise DataError(f"{name} has {a.shape[-1]} columns, the robot {n} joints ({', '.join(self.joint_names)})"
                                f": give shape ({n},) or (N, {n})")
            one = a.ndim == 1
            if single is not None and one != single:
                raise DataError(f"{', '.join(arrays)} must all be one state (n,) or all (N, n)")
            single = one
            out.append(np.ascontiguousarray(np.atleast_2d(a)))
        if len({len(a) for a in out}) > 1:
            raise DataError(f"{', '.join(arrays)} must have the same number of rows, got "
                            + ", ".join(str(len(a)) for a in out))
        return out, bool(single)

    def rnea(self, q, v, a) -> np.ndarray:
        """Inverse dynamics: the joint torques (forces on prismatic joints) that give accelerations ``a`` at
        positions ``q`` and speeds ``v``, gravity included."""
        (q, v, a), one = self._states(q=q, v=v, a=a)
        out = self._core.rnea(q, v, a)
        return out[0] if one else out

    def _armature(self, armature) -> Optional[List[float]]:
        """The rotor inertias reflected to the joints (n,) as the core takes them, or None."""
        if armature is None:
            return None
        arm = [float(x) for x in _checks.real_array("armature", armature, (1,))]
        if len(arm) != self.ndof:
            raise DataError(f"armature has {len(arm)} values, the robot {self.ndof} joints")
        return arm

    def _split(self, out: np.ndarray, matrices: int, one: bool):
        """The core's rows (N, n + k n²) of a value and its ``matrices`` derivatives: ((N, n), (N, n, n) × k), or
        each of one state."""
        n = self.ndof
        parts = [out[:, :n]] + [out[:, n + k * n * n:n + (k + 1) * n * n].reshape(-1, n, n) for k in range(matrices)]
        return tuple(p[0] for p in parts) if one else tuple(parts)

    def rnea_derivatives(self, q, v, a):
        """Inverse dynamics with its exact partial derivatives: ``(tau, dtau_dq, dtau_dv)``, the torques (n,) and
        ``∂τ/∂q``, ``∂τ/∂q̇`` (n, n; entry (i, j) is ∂τ_i/∂x_j), or (N, n) and (N, n, n) for N states (``∂τ/∂q̈`` is
        :meth:`mass_matrix`). Newton-Euler differentiated along each coordinate (forward mode), exact to rounding:
        the linearization of the arm's dynamics, ``∂q̈/∂x = −M⁻¹ ∂τ/∂x``, as Pinocchio's
        ``computeRNEADerivatives`` gives it."""
        (q, v, a), one = self._states(q=q, v=v, a=a)
        return self._split(self._core.rnea_derivatives(q, v, a), 2, one)

    def aba_derivatives(self, q, v, tau, armature=None):
        """Forward dynamics with its exact partial derivatives: ``(qdd, dqdd_dq, dqdd_dv, dqdd_dtau)``, the
        accelerations (n,) and ``∂q̈/∂q``, ``∂q̈/∂q̇``, ``∂q̈/∂τ`` (the inverse mass matrix; n, n each), or (N, n) and
        (N, n, n) for N states; ``armature`` (n,) as for :meth:`aba`. ``∂q̈/∂x = −(M + A)⁻¹ ∂τ/∂x`` from
        :meth:`rnea_derivatives` at the accelerations: Pinocchio's ``computeABADerivatives``."""
        (q, v, tau), one = self._states(q=q, v=v, tau=tau)
        arm = self._armature(armature)
        return self._split(self._core.aba_derivatives(q, v, tau, arm), 3, one)

    def aba(self, q, v, tau, armature=None) -> np.ndarray:
        """Forward dynamics: the accelerations that torques ``tau`` give at ``q``, ``v``; ``armature`` (n,): rotor
        inertias reflected to the joints, added to the mass matrix's diagonal."""
        (q, v, tau), one = self._states(q=q, v=v, tau=tau)
        arm = self._armature(armature)
        out = self._core.aba(q, v, tau, arm)
        return out[0] if one else out

    def gravity(self, q) -> np.ndarray:
        """The joint torques that hold the robot still against gravity at positions ``q``."""
        (q,), one = self._states(q=q)
        out = self._core.gravity(q)
        return out[0] if one else out

    def mass_matrix(self, q) -> np.ndarray:
        """The joint-space mass matrix at ``q``: (n, n), or (N, n, n)."""
        (q,), one = self._states(q=q)
        out = self._core.mass_matrix(q)
        return out[0] if one else out

    def regressor(self, q, v, a, columns=None, by_joint: bool = False) -> np.ndarray:
        """The inverse-dynamics regressor: (n, 10 n), or (N, n, 10 n), with
        ``rnea(q, v, a) = regressor(q, v, a) @ inertial_params``; with ``columns`` (indices of standard
        parameters), only their columns, ``regressor(q, v, a)[..., columns]`` without storing the others.
        ``by_joint`` (N states only): laid out (n, m, N), ``regressor(q, v, a).transpose(1, 2, 0)``, each joint's
        columns contiguous series over the states (``[j].T`` is a column-major N × m matrix)."""
        (q, v, a), one = self._states(q=q, v=v, a=a)
        cols = None
        if columns is not None:
            c = np.asarray(columns).ravel()
            p = 10 * self.ndof
            if c.size and (not np.issubdtype(c.dtype, np.integer) or np.any((c < 0) | (c >= p))):
                raise DataError(f"regressor columns must be indices of the {p} standard parameters, got {columns!r}")
            cols = [int(x) for x in c]
        if by_joint:
            if one:
                raise DataError("regressor(..., by_joint=True) takes N states (arrays of shape (N, n))")
            return self._core.regressor(q, v, a, cols, True)
        out = self._core.regressor(q, v, a, cols)
        return out[0] if one else out


@dataclass(frozen=True)
class BaseParameters:
    """The map β = K·π from the standard parameters π (rotor inertias, then 10 per body) to the base parameters."""

    standard_names: Tuple[str, ...]
    names: Tuple[str, ...]
    K: np.ndarray
    independent: Tuple[int, ...]

    def of(self, pi: np.ndarray) -> np.ndarray:
        return self.K @ pi

    @property
    def bodies_only(self) -> Tuple[str, ...]:
        """The base parameters the bodies alone make, no rotor inertia in them (by the map, not by their names): what
        a manufacturer's body data gives, to hold while the drives are fitted (``frozen``)."""
        n = len(self.standard_names) // 11  # one rotor inertia, then ten body parameters, per joint
        return tuple(nm for i, nm in enumerate(self.names) if not np.any(self.K[i, :n]))

    def standard_from(self, beta: np.ndarray, anchor: np.ndarray) -> np.ndarray:
        """The standard parameters closest to ``anchor`` (the URDF's, say) whose base parameters are ``beta``: every
        such set gives the same dynamics."""
        return anchor + np.linalg.lstsq(self.K, beta - self.K @ anchor, rcond=None)[0]


__all__ = ["Robot", "BaseParameters"]
