"""One trial of one session as viewer entries (spec chapter 2 streams): the raw streams as they are and,
per the ``derived`` mode, what the reference derives from them (calibrated hand signals §7.5, plate force and
COP, DFT321 §10.3, contact signals §12–13, the free-space force field §9.5, workspace meshes §8.2–8.4).
:class:`CachedStreams` reads each stream table once per trial (spec §3.2, §4.8)."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
import rerun as rr

from haptify.codes import Code
from haptify.errors import HaptifyError, fail
from haptify.formats.conventions import quat_multiply, quat_rotate
from haptify.formats.session_format import Kinematics, Stream, Trial
from haptify.formats.storage import SessionFolder
from haptify_tools.viewer.arrays import columns_of, finite_rows, nan_split, plane_rectangle, raw_pose_at, xyzw
from haptify_tools.viewer.plan import (
    FORCE_COLORS,
    HAND_FORCE_M_PER_N,
    HANDLE_AXIS_M,
    LINK_AXIS_M,
    LINK_PALETTE,
    MESH_ALPHA,
    MODELED_COLOR,
    PLATE_FORCE_COLOR,
    PLATE_FORCE_M_PER_N,
    ROLE_COLORS,
    SERIES,
    SERIES_COLORS,
    Entry,
    Plan,
    time_ns,
)
from haptify_tools.viewer.voxel_mesh import boundary_mesh

if TYPE_CHECKING:  # imported where used: a raw-only recording needs neither (start-up time)
    from haptify.pipeline.compute import ComputeContext


class CachedStreams(SessionFolder):
    """A session whose stream tables are read once per trial (spec §3.2 reading, unchanged).

    Reads go through the wrapped session (so a checked session validates each stream on its first
    read, spec §4.8). The planner and the reference functions it calls (``haptify.processing.signals``,
    ``haptify.processing.force_plate``) read the same streams; each caller gets a shallow copy, so replacing a
    column never leaks. :meth:`forget` drops the tables once a trial is written, so at most one
    trial's tables are in memory.
    """

    def __init__(self, session: SessionFolder) -> None:
        super().__init__(session.root, session.manifest, session.raw)
        self._inner = session
        self._tables: dict[tuple, pd.DataFrame] = {}

    def read_stream(self, stream: Stream, *, verify: bool = False, session_clock: bool = True) -> pd.DataFrame:
        key = (stream.file, verify, session_clock)
        if key not in self._tables:
            self._tables[key] = self._inner.read_stream(stream, verify=verify, session_clock=session_clock)
        return self._tables[key].copy(deep=False)

    def forget(self) -> None:
        self._tables.clear()


def series_entry(
    path: str, key: str, t: np.ndarray, values: np.ndarray, names: list[str], role: str, stream: str, derived: bool = False
) -> Entry:
    """A time series: one row of ``len(names)`` scalars per sample, at the samples' exact times.
    ``t`` in s on the session clock, spec §1.4.

    Legend entries read ``name [unit]`` (unit from ``SERIES``), with ``(compare)`` for the compared session.
    """
    values = np.asarray(values, dtype=np.float64).reshape(len(t), len(names))
    palette = SERIES_COLORS[role]
    suffix = f" [{SERIES[key][1]}]" + ("" if role == "measured" else f" ({role})")
    lines = rr.SeriesLines(names=[f"{n}{suffix}" for n in names], colors=[palette[i % len(palette)] for i in range(len(names))])
    return Entry(
        path,
        static=[lines],
        times_ns=time_ns(t),
        archetype=rr.Scalars,
        fields={"scalars": values},
        series=key,
        stream=stream,
        derived=derived,
    )


class TrialPlanner:
    """Turns one trial of one session (one role) into entries (spec chapter 2 streams)."""

    def __init__(self, session: CachedStreams, ctx: ComputeContext | None, trial: Trial, role: str, key: str, plan: Plan) -> None:
        self.ctx = ctx  # shares calibration, handle and plate signals between the reference functions (None: derived off)
        self.session = session
        self.trial = trial
        self.role = role
        self.plan = plan
        self.world = f"/world/{key}/{role}"
        self.series = f"/series/{key}/{role}"
        self.kinds = {s.kind for s in trial.streams}
        self.rig = self.session.manifest.rig
        self._signals: Any = None  # signals.HandleSignals
        self._signals_tried = False

    def read(self, kind: str) -> pd.DataFrame | None:
        if kind not in self.kinds:
            return None
        return self.session.read(self.trial.id, kind)

    @property
    def derive(self) -> bool:
        """Whether derived signals are computed at all (``derived`` is not ``off``)."""
        return self.plan.derived != "off"

    def add_series(
        self, key: str, t: np.ndarray, values: np.ndarray, names: list[str], stream: str, derived: bool = False
    ) -> None:
        self.plan.add(series_entry(f"{self.series}/{key}", key, t, values, names, self.role, stream, derived))

    def run(self) -> None:
        pose = self.read("handle_pose")
        p = q = t_pose = None
        if pose is not None:
            t_pose = pose["t"].to_numpy()
            p = columns_of(pose, ["px", "py", "pz"])
            q = columns_of(pose, ["qw", "qx", "qy", "qz"])
            self.handle(t_pose, p, q)
        self.wrench(t_pose, p, q)
        self.accel()
        self.plate()
        self.commanded()
        self.device_and_sync()
        self.markers()
        self.links()
        if p is not None and self.trial.protocol == "workspace":
            self.workspace(p[finite_rows(p)])
        self.session.forget()
        if self.trial.rendering is not None:
            self.surface(t_pose, p)

    def workspace(self, points: np.ndarray) -> None:
        """The measured cloud, and the measured and modeled workspaces as meshes (spec §8.2–8.4)."""
        self.plan.add(
            Entry(f"{self.world}/workspace/points", static=[rr.Points3D(points, radii=0.0015, colors=ROLE_COLORS[self.role])])
        )
        if not self.derive:
            return
        from haptify.metrics import workspace

        try:
            solid = workspace.volume_solid(points)
        except HaptifyError as err:
            self.note("measured workspace mesh", err)
        else:
            self.add_solid("measured workspace mesh", f"{self.world}/workspace/measured", solid, ROLE_COLORS[self.role])
        kin = self.session.device().kinematics
        if kin is None:
            self.note(
                "modeled workspace mesh",
                fail(Code.DEVICE_KINEMATICS_MISSING, "the device has no kinematics", pointer="/device/kinematics"),
            )
            return
        place = self.session.manifest.device_placement
        try:
            model = modeled_solid(kin.model_dump_json(), tuple(place.position), tuple(place.quaternion))
        except HaptifyError as err:
            self.note("modeled workspace mesh", err)
        else:
            self.add_solid("modeled workspace mesh", f"{self.world}/workspace/modeled", model, MODELED_COLOR)

    def handle(self, t: np.ndarray, p: np.ndarray, q: np.ndarray) -> None:
        """Handle pose with axes, the gimbal-centre path and the position time series."""
        ok = finite_rows(p, q)
        self.plan.add(
            Entry(
                f"{self.world}/handle",
                static=[rr.TransformAxes3D(HANDLE_AXIS_M)],
                times_ns=time_ns(t[ok]),
                archetype=rr.Transform3D,
                fields={"translation": p[ok], "quaternion": xyzw(q[ok])},
                stream="handle_pose",
            )
        )
        strips = nan_split(p)
        if strips:
            self.plan.add(
                Entry(f"{self.world}/trajectory", static=[rr.LineStrips3D(strips, radii=0.0008, colors=ROLE_COLORS[self.role])])
            )
        self.add_series("handle/position", t, p, ["px", "py", "pz"], "handle_pose")

    def note(self, what: str, err: HaptifyError) -> None:
        """Record why a derived quantity is missing (shown in the /session document)."""
        f = err.findings[0]
        self.plan.notes.append(f"{self.trial.id} ({self.role}): {what} not shown — {f.code} {f.message}")

    def add_solid(self, what: str, path: str, solid: Any, color: tuple[int, int, int]) -> None:
        """A voxel solid as a mesh, or a W410 note when nothing is inside (the sweep did not close)."""
        entry = solid_entry(path, solid, color, compact=self.plan.derived == "compact")
        if entry is None:
            self.plan.notes.append(f"{self.trial.id} ({self.role}): {what} not shown — W410 the points enclose no volume")
        else:
            self.plan.add(entry)

    def handle_signals(self) -> Any:
        """The calibrated handle signals (spec §7.5, ``signals.HandleSignals``), once per trial; None (with a
        note) when unavailable, and None without computing anything when derived signals are off."""
        if not self._signals_tried and self.derive:
            from haptify.processing import signals

            self._signals_tried = True
            if "handle_pose" in self.kinds and self.kinds & {"handle_wrench", "handle_accel"}:
                try:
                    self._signals = signals.handle_signals(self.ctx, self.trial.id)
                except HaptifyError as err:
                    self.note("calibrated handle force and acceleration", err)
        return self._signals

    def force_arrows(self, path: str, t: np.ndarray, origins: np.ndarray, force: np.ndarray, stream: str) -> None:
        ok = finite_rows(origins, force)
        self.plan.add(
            Entry(
                path,
                times_ns=time_ns(t[ok]),
                static=[rr.Arrows3D.from_fields(colors=FORCE_COLORS[self.role], radii=0.001)],
                archetype=rr.Arrows3D,
                fields={"origins": origins[ok], "vectors": force[ok] * HAND_FORCE_M_PER_N},
                stream=stream,
                derived=True,
            )
        )

    def wrench(self, t_pose: np.ndarray | None, p: np.ndarray | None, q: np.ndarray | None) -> None:
        """Raw F/T series (sensor frame), and the hand force in W as series, arrow and free-space field.

        The hand force is the calibrated wrench when the session's calibration allows it (spec §7.5);
        otherwise the raw F/T force rotated to W with the unfiltered pose (bias and weight still in).
        """
        w = self.read("handle_wrench")
        if w is None:
            return
        t = w["t"].to_numpy()
        f = columns_of(w, ["fx", "fy", "fz"])
        self.add_series("handle/force_raw", t, f, ["fx", "fy", "fz"], "handle_wrench")
        self.add_series("handle/torque_raw", t, columns_of(w, ["tx", "ty", "tz"]), ["tx", "ty", "tz"], "handle_wrench")
        hs = self.handle_signals()
        if hs is not None and hs.force is not None:
            self.add_series("hand_force/calibrated", hs.t, hs.force, ["fx", "fy", "fz"], "handle_signals", derived=True)
            self.add_series("hand_torque/calibrated", hs.t, hs.torque, ["tx", "ty", "tz"], "handle_signals", derived=True)
            shown = (hs.t, hs.position, hs.force, "handle_signals", "calibrated")
        elif self.derive and t_pose is not None and p is not None and q is not None and self.rig.handle is not None:
            pose = raw_pose_at(t_pose, p, q, t)
            q_sensor = np.asarray(self.rig.handle.ft_sensor.pose.quaternion, dtype=np.float64)
            with np.errstate(invalid="ignore"):
                f_w = quat_rotate(quat_multiply(pose.quaternion, q_sensor), f)
            self.add_series("hand_force/raw_world", t, f_w, ["fx", "fy", "fz"], "handle_wrench", derived=True)
            shown = (t, pose.position, f_w, "handle_wrench", "raw")
        else:
            shown = None
        if shown is None:
            return
        t_a, origins, force, stream, label = shown
        self.force_arrows(f"{self.world}/hand_force/{label}", t_a, origins, force, stream)
        ok = finite_rows(origins, force)
        if self.trial.protocol == "free_space" and ok.any():
            from haptify.metrics import free_space

            field_ = free_space.force_field(origins[ok], force[ok])  # the spec's binning (§9.5)
            if len(field_.centres):
                self.plan.add(
                    Entry(
                        f"{self.world}/force_field",
                        static=[
                            rr.Arrows3D(
                                origins=field_.centres,
                                vectors=field_.mean_force * HAND_FORCE_M_PER_N,
                                colors=FORCE_COLORS[self.role],
                                radii=0.0006,
                            )
                        ],
                        derived=True,
                    )
                )

    def accel(self) -> None:
        a = self.read("handle_accel")
        if a is not None:
            self.add_series("accel/raw", a["t"].to_numpy(), columns_of(a, ["ax", "ay", "az"]), ["ax", "ay", "az"], "handle_accel")
            hs = self.handle_signals()
            if hs is not None and hs.acceleration is not None:
                self.add_series("accel/world", hs.t, hs.acceleration, ["ax", "ay", "az"], "handle_signals", derived=True)
            if not self.derive:
                return
            from haptify.metrics import vibration

            try:
                vib = vibration.trial_vibration(self.ctx, self.trial.id)
            except HaptifyError as err:
                self.note("DFT321 vibration signal", err)
            else:
                self.add_series("accel/dft321", vib.t, vib.signal, ["dft321"], "vibration", derived=True)

    def plate(self) -> None:
        w = self.read("plate_wrench")
        if w is None:
            return
        t = w["t"].to_numpy()
        names_f = [f"c{i}_f{a}" for i in range(1, 5) for a in "xyz"]
        names_t = [f"c{i}_t{a}" for i in range(1, 5) for a in "xyz"]
        self.add_series("plate/corner_force_raw", t, columns_of(w, names_f), names_f, "plate_wrench")
        self.add_series("plate/corner_torque_raw", t, columns_of(w, names_t), names_t, "plate_wrench")
        if not self.derive:
            return
        from haptify.processing import force_plate

        try:
            ps = force_plate.plate_signals(self.ctx, self.trial.id)
        except HaptifyError as err:
            self.note("plate total force and COP", err)
            return
        self.add_series("plate/force", ps.t, ps.force, ["Fx", "Fy", "Fz"], "plate_signals", derived=True)
        self.add_series("plate/cop", ps.t, ps.cop, ["x", "y"], "plate_signals", derived=True)
        # The force on the plate drawn as an arrow whose head is at the COP (on the top surface, z = 0).
        ok = ps.cop_valid & finite_rows(ps.force)
        head = np.column_stack([ps.cop[ok], np.zeros(int(ok.sum()))])
        vec = ps.force[ok] * PLATE_FORCE_M_PER_N
        self.plan.add(
            Entry(
                f"{self.world}/plate_force",
                times_ns=time_ns(ps.t[ok]),
                static=[rr.Arrows3D.from_fields(colors=PLATE_FORCE_COLOR, radii=0.002)],
                archetype=rr.Arrows3D,
                fields={"origins": head - vec, "vectors": vec},
                stream="plate_signals",
                derived=True,
            )
        )

    def commanded(self) -> None:
        c = self.read("commanded_wrench")
        if c is None:
            return
        t = c["t"].to_numpy()
        self.add_series("commanded/force", t, columns_of(c, ["fx", "fy", "fz"]), ["fx", "fy", "fz"], "commanded_wrench")
        self.add_series("commanded/torque", t, columns_of(c, ["tx", "ty", "tz"]), ["tx", "ty", "tz"], "commanded_wrench")

    def device_and_sync(self) -> None:
        """The device's own joint angles (diagnostic, spec §2.6) and the sync trigger, as they are."""
        q = self.read("device_joint_angles")
        if q is not None:
            names = [c for c in q.columns if c != "t"]
            self.add_series("device/joint_angles", q["t"].to_numpy(), columns_of(q, names), names, "device_joint_angles")
        s = self.read("sync")
        if s is not None:
            self.add_series("sync/trigger", s["t"].to_numpy(), columns_of(s, ["trigger"]), ["trigger"], "sync")

    def read_entities(self, kind: str) -> tuple[list[str], pd.DataFrame, np.ndarray] | None:
        """Entity names, table and time column of a per-entity stream (markers, link_poses), or None."""
        stream = self.session.stream(self.trial.id, kind)
        if stream is None:
            return None
        frame = self.session.read_stream(stream)
        return list(stream.entities or []), frame, frame["t"].to_numpy()

    def markers(self) -> None:
        """The markers of each rigid body (link) as one labelled point cloud, a colour per link: one row per
        frame where any of them is known, an occluded marker's position NaN (not drawn) in that row."""
        found = self.read_entities("markers")
        if found is None:
            return
        entities, frame, t = found
        owner: dict[str, str] = {}  # marker → its rigid body
        if self.rig.motion_capture is not None:
            for body in self.rig.motion_capture.rigid_bodies:
                for m in body.markers:
                    owner.setdefault(m, body.name)
        groups: dict[str, list[str]] = {}
        for m in entities:
            groups.setdefault(owner.get(m, "unassigned"), []).append(m)
        for i, (link, names) in enumerate(groups.items()):
            xyz = columns_of(frame, [f"{m}_{a}" for m in names for a in "xyz"]).reshape(len(t), len(names), 3)
            ok = np.isfinite(xyz).all(axis=2).any(axis=1)
            self.plan.add(
                Entry(
                    f"{self.world}/markers/{rr.escape_entity_path_part(link)}",
                    static=[rr.Points3D.from_fields(colors=LINK_PALETTE[i % len(LINK_PALETTE)], radii=0.002, labels=names)],
                    times_ns=time_ns(t[ok]),
                    archetype=rr.Points3D,
                    fields={"positions": xyz[ok]},
                    stream="markers",
                )
            )

    def links(self) -> None:
        """Each link's frame from link_poses, with axes."""
        found = self.read_entities("link_poses")
        if found is None:
            return
        entities, frame, t = found
        for link in entities:
            p = columns_of(frame, [f"{link}_p{a}" for a in "xyz"])
            q = columns_of(frame, [f"{link}_q{a}" for a in "wxyz"])
            ok = finite_rows(p, q)
            self.plan.add(
                Entry(
                    f"{self.world}/links/{rr.escape_entity_path_part(link)}",
                    static=[rr.TransformAxes3D(LINK_AXIS_M)],
                    times_ns=time_ns(t[ok]),
                    archetype=rr.Transform3D,
                    fields={"translation": p[ok], "quaternion": xyzw(q[ok])},
                    stream="link_poses",
                )
            )

    def surface(self, t_pose: np.ndarray | None, p: np.ndarray | None) -> None:
        """The rendered plane as a translucent rectangle, and the handle's penetration series."""
        r = self.trial.rendering
        if r is None:  # a trial without a rendered plane has none to draw
            return
        point = np.asarray(r.surface_point_m, dtype=np.float64)
        normal = np.asarray(r.surface_normal, dtype=np.float64)
        norm = float(np.linalg.norm(normal))
        if not (np.isfinite(norm) and norm > 0.0):
            from haptify.metrics.surface import unit_normal

            unit_normal(normal, self.trial.id)  # the reference's coded error (E303)
        normal = normal / norm
        around = p[finite_rows(p)] if p is not None else None
        corners = plane_rectangle(point, normal, around)
        self.plan.add(
            Entry(
                f"{self.world}/virtual_surface",
                static=[
                    rr.Mesh3D(
                        vertex_positions=corners,
                        triangle_indices=[[0, 1, 2], [0, 2, 3]],
                        vertex_normals=np.tile(normal, (4, 1)),
                        albedo_factor=(*ROLE_COLORS[self.role], 90),
                    )
                ],
            )
        )
        if t_pose is not None and p is not None:
            depth = (point - p) @ normal
            self.add_series("penetration", t_pose, depth, ["depth"], "handle_pose")
        if self.derive and {"commanded_wrench", "handle_wrench", "handle_pose"} <= self.kinds:
            from haptify.metrics import surface

            try:
                cs = surface.contact_signals(self.ctx, self.trial.id)
            except HaptifyError as err:
                self.note("contact signals (normal force, contact)", err)
                return
            self.add_series(
                "contact/normal_force",
                cs.t,
                np.column_stack([cs.commanded_normal, cs.normal_force]),
                ["commanded Fn", "felt Fn"],
                "handle_signals",
                derived=True,
            )
            self.add_series("contact/penetration", cs.t, cs.penetration, ["depth"], "handle_signals", derived=True)
            self.add_series(
                "contact/state",
                cs.t,
                np.column_stack([cs.contact, cs.used]).astype(np.float64),
                ["contact", "used"],
                "handle_signals",
                derived=True,
            )


@functools.lru_cache(maxsize=4)
def modeled_solid(kinematics_json: str, position: tuple, quaternion: tuple) -> Any:
    """``haptify.metrics.workspace.modeled_solid`` (spec §8.3, a ``VoxelSolid``), computed once per device model and placement."""
    from haptify.metrics import workspace

    kin = Kinematics.model_validate_json(kinematics_json)
    return workspace.modeled_solid(kin, position, quaternion)


def solid_entry(path: str, solid: Any, color: tuple[int, int, int], compact: bool = False) -> Entry | None:
    """A voxel solid's boundary (voxels with fraction ≥ 0.5) as a translucent static mesh; None when empty.
    The fractions of spec §8.4 step 5. ``compact``: each lattice corner once, no normals (``SurfaceMesh.shared``)."""
    mesh = boundary_mesh(solid.fraction >= 0.5, solid.origin, solid.pitch)
    if not len(mesh.triangles):
        return None
    if compact:
        vertices, triangles = mesh.shared(solid.pitch)
        drawn = rr.Mesh3D(vertex_positions=vertices, triangle_indices=triangles, albedo_factor=(*color, MESH_ALPHA))
    else:
        drawn = rr.Mesh3D(
            vertex_positions=mesh.vertices,
            triangle_indices=mesh.triangles,
            vertex_normals=mesh.normals,
            albedo_factor=(*color, MESH_ALPHA),
        )
    return Entry(path, static=[drawn], derived=True)
