"""The gravity-loaded breast as a dolfinx variational problem.

Unknowns: displacement u (and, for Taylor–Hood, pressure p). Total potential

    Π(u, p) = ∫ [C1 (Ī1 - 3) - p (J - 1)] dX - ∫ ρ λ g · u dX  [+ Π_c(u)] [+ Π_sc(u)],

with λ ∈ [0, 1] the load fraction, the material's terms (the solid's law with each cell's C1,
the skin's membrane) from :mod:`fem.materials`, Π_c the optional contact penalty with the chest
(:mod:`fem.contact`) and Π_sc the skin's optional self-contact penalty
(:mod:`fem.self_contact`, assembled outside UFL by the solver). The residual is Π's first
variation and the Jacobian its second, so the discrete tangent is symmetric (used by MUMPS LDLᵀ).
C1 and the body force are ``fem.Constant`` objects: one compiled form serves a
whole sweep and the load steps within a case.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from fem.contact import Contact
from fem.exceptions import InvalidParameterError, MeshError
from fem.io import boundary_vertex_nodes, node_to_vertex_dof
from fem.kinematics import deformation_gradient, jacobian
from fem.materials import SkinLayer, Tissues
from fem.materials.mesh_material import MeshMaterial
from fem.parameters import Discretisation, FixedBoundaries, Gravity, Material
from fem.pressure_modes import pinned_pressure_bcs
from fem.self_contact import SelfContact, SelfContactAssembler
from fem.skin_surface import SkinSurface
from meshes.io import boundary_facets, geometry_nodes
from meshes.tags import Boundary

log = logging.getLogger(__name__)


def check_mesh(mesh: Any, facet_tags: Any, fixed: FixedBoundaries) -> None:
    """Reject meshes the solver cannot use, naming the problem.

    Raises:
        MeshError: if a fixed boundary has no facets, or cells are degenerate or inverted.
    """
    comm = mesh.comm
    for boundary, _ in fixed.items():
        n = comm.allreduce(len(boundary_facets(facet_tags, [boundary])), op=MPI.SUM)
        if n == 0:
            raise MeshError(
                f"the mesh has no facets tagged {boundary.label!r} (tag {int(boundary)}), "
                "which the configuration fixes"
            )
    x = mesh.geometry.x
    nodes = geometry_nodes(mesh)[:, :4]
    n_local = mesh.topology.index_map(mesh.topology.dim).size_local
    nodes = nodes[:n_local]
    e1, e2, e3 = (x[nodes[:, i]] - x[nodes[:, 0]] for i in (1, 2, 3))
    signed = np.einsum("ij,ij->i", np.cross(e1, e2), e3) / 6.0
    scale = comm.allreduce(float(np.max(np.abs(signed), initial=0.0)), op=MPI.MAX)
    degenerate = comm.allreduce(int(np.sum(np.abs(signed) <= 1e-10 * scale)), op=MPI.SUM)
    if degenerate:
        raise MeshError(f"the mesh has {degenerate} degenerate (zero-volume) cells")
    positive = comm.allreduce(int(np.sum(signed > 0)), op=MPI.SUM)
    negative = comm.allreduce(int(np.sum(signed < 0)), op=MPI.SUM)
    if positive and negative:
        raise MeshError(
            f"the mesh has inverted cells: {min(positive, negative)} of "
            f"{positive + negative} cells are oriented opposite to the rest"
        )


class GravityProblem:
    """Function spaces, forms and boundary conditions of one mesh.

    Args:
        mesh: dolfinx mesh (metres).
        facet_tags: facet tags with :class:`meshes.tags.Boundary` values.
        discretisation: element choice.
        fixed: which boundaries are clamped.
        contact: penalty contact of the skin with a rigid obstacle (:mod:`fem.contact`);
            its energy joins the potential on the skin. None: no contact.
        self_contact: the skin's contact with itself (:mod:`fem.self_contact`; serial
            only). None: the skin may pass through itself.
        cell_tags: cell tags with :class:`meshes.tags.Tissue` values (None: all fat).
        tissues: each tissue's stiffness over the fat's (:mod:`fem.materials.tissues`; None: the
            defaults).
        skin: the skin as a membrane on the skin boundary (None: none); left out, with a
            note in the log, where the cell tags already hold skin cells.
    """

    def __init__(
        self,
        mesh: Any,
        facet_tags: Any,
        discretisation: Discretisation = Discretisation(),
        fixed: FixedBoundaries = FixedBoundaries(),
        contact: Contact | None = None,
        self_contact: SelfContact | None = None,
        cell_tags: Any = None,
        tissues: Tissues | None = None,
        skin: SkinLayer | None = None,
    ) -> None:
        check_mesh(mesh, facet_tags, fixed)
        self.mesh = mesh
        #: Counts :meth:`set_geometry`'s moves (what was measured on a geometry keys on it).
        self.geometry_version = 0
        self.facet_tags = facet_tags
        self.discretisation = discretisation
        self.fixed = fixed
        self.mixed = discretisation.element == "taylor-hood"
        cell = mesh.ufl_cell()

        scalar = PETSc.ScalarType
        #: The material laws on this mesh (:mod:`fem.materials`): the weak form's material
        #: terms, each cell's C1 (:attr:`MeshMaterial.local_C1`) and the skin membrane.
        self.material = MeshMaterial(mesh, discretisation, cell_tags, tissues, skin)
        #: The case's C1 (Pa), the fat's; the contact penalties take it
        #: (:mod:`fem.materials.tissues`).
        self.C1 = self.material.C1
        self.body_force = fem.Constant(mesh, np.zeros(3, dtype=scalar))
        self.density = 0.0
        self.gravity = np.zeros(3)

        if self.mixed:
            k = discretisation.degree
            element = ufl.MixedElement(
                [ufl.VectorElement("Lagrange", cell, k), ufl.FiniteElement("Lagrange", cell, k - 1)]
            )
            self.W = fem.FunctionSpace(mesh, element)
            self.w = fem.Function(self.W, name="state")
            u, p = ufl.split(self.w)
            self.V, _ = self.W.sub(0).collapse()
            #: The pressure's entries in the state's array (the others: the displacement's).
            self.pressure_dofs = np.asarray(self.W.sub(1).collapse()[1], dtype=np.int64)
        else:
            self.W = fem.VectorFunctionSpace(mesh, ("Lagrange", 1))
            self.w = fem.Function(self.W, name="state")
            u, p = self.w, None
            self.V = self.W
            self.pressure_dofs = np.zeros(0, dtype=np.int64)
        self._u_expr = u

        dx = ufl.Measure(
            "dx", domain=mesh, metadata={"quadrature_degree": discretisation.quadrature}
        )
        self.dx = dx
        self.contact = contact
        self._contact_nodes = np.zeros(0, dtype=np.int64)  # owned skin vertices in the zone
        # kept: the preconditioner's pressure block must use these very arguments
        self._test, self._trial = ufl.TestFunction(self.W), ufl.TrialFunction(self.W)
        residual = self._weak_form(u, p)
        tangent = ufl.derivative(residual, self.w, self._trial)
        self._tangent_ufl = tangent
        self.residual = fem.form(residual)
        self.tangent = fem.form(tangent)
        self._preconditioner: fem.FormMetaClass | None = None
        self.bcs = self._dirichlet_bcs()
        # a pressure no free displacement sees (a cell with every node clamped): pinned
        pinned = pinned_pressure_bcs(self.W, self.bcs) if self.mixed else []
        #: Pressure unknowns pinned (over the processes): no free displacement sees them.
        self.pinned_pressure_dofs = mesh.comm.allreduce(
            sum(int(bc.dof_indices()[1]) for bc in pinned), op=MPI.SUM)
        self.bcs += pinned
        #: The clamped entries of the state's local array.
        self.fixed_mask = np.zeros(self.w.x.array.size, dtype=bool)
        for bc in self.bcs:
            self.fixed_mask[bc.dof_indices()[0]] = True
        self.self_contact = self._self_contact_assembler(self_contact)
        self._volume_form = fem.form(fem.Constant(mesh, scalar(1.0)) * dx)
        self._volume = self._measure_volume()
        self._volume_change = fem.form((self.J - 1) * dx)
        self._detF_points = self._quadrature_points(discretisation.quadrature)
        self._detF = fem.Expression(self.J, self._detF_points)
        n_local = mesh.topology.index_map(mesh.topology.dim).size_local
        self._cells = np.arange(n_local, dtype=np.int32)

    #: The tangent is symmetric (the second variation of a potential): LDLᵀ factorises it.
    symmetric = True

    def _weak_form(self, u: ufl.core.expr.Expr, p: ufl.core.expr.Expr | None) -> ufl.Form:
        """The residual: the first variation of the total potential, on the reference mesh.

        Sets ``J`` (det F, for the volume and inversion checks) and, with contact, the
        contact zone's skin vertices and the contact force's form.
        """
        mesh, dx, contact = self.mesh, self.dx, self.contact
        F = deformation_gradient(u)
        self.J = jacobian(F)
        psi = self.material.strain_energy(F, p)
        potential = psi * dx - ufl.dot(self.body_force, u) * dx
        membrane = self.material.skin_energy(F, ufl.FacetNormal(mesh))
        if membrane is not None:
            potential += membrane * self.skin_measure()(int(Boundary.SKIN))
        if contact is not None:
            ds = self.skin_measure()
            x = ufl.SpatialCoordinate(mesh)
            potential += contact.energy(x, u, self.C1) * ds(int(Boundary.SKIN))
            skin = boundary_vertex_nodes(mesh, self.facet_tags, [Boundary.SKIN])
            zone = contact.obstacle.gap_values(mesh.geometry.x[skin]) >= contact.clearance
            self._contact_nodes = skin[zone]
            self._contact_force = fem.form(contact.pressure(x, u, self.C1) * ds(int(Boundary.SKIN)))
        return ufl.derivative(potential, self.w, self._test)

    def _self_contact_assembler(self, settings: SelfContact | None) -> SelfContactAssembler | None:
        if settings is None:
            return None
        if self.mesh.comm.size > 1:
            raise InvalidParameterError(
                "fe.self_contact is serial: its pairs join nodes that a distributed mesh holds "
                "on different processes; run on one process or set fe.self_contact: null"
            )
        facets = boundary_facets(self.facet_tags, [Boundary.SKIN])
        surface = SkinSurface.from_problem(self.W, self.mixed, self.mesh, facets)
        return SelfContactAssembler(settings, surface)

    def add_self_contact_residual(self, b: np.ndarray) -> None:
        """Add the self-contact's residual at the current state to ``b`` (a local array)."""
        if self.self_contact is not None:
            self.self_contact.add_residual(b, self.w.x.array, float(self.C1.value))

    def add_self_contact_tangent(self, A: PETSc.Mat) -> None:
        """Add the self-contact's tangent at the current state to ``A``.

        Call before ``A``'s final assembly; clamped rows and columns are left out.
        """
        if self.self_contact is not None:
            self.self_contact.add_tangent(A, self.w.x.array, float(self.C1.value),
                                          self.fixed_mask)

    def self_contact_status(self) -> dict[str, Any] | None:
        """The self-contact's state at the current displacement; None without self-contact.

        The force (N), skin area in contact (cm²), deepest penetration (mm), largest pressure
        (Pa), pairs and the search's cost (:meth:`SelfContactAssembler.status`).
        """
        if self.self_contact is None:
            return None
        return self.self_contact.status(self.w.x.array, float(self.C1.value))

    def skin_measure(self) -> ufl.Measure:
        """The boundary measure over the facet tags, at the forms' quadrature degree."""
        return ufl.Measure(
            "ds",
            domain=self.mesh,
            subdomain_data=self.facet_tags,
            metadata={"quadrature_degree": self.discretisation.quadrature},
        )

    @property
    def preconditioner(self) -> fem.FormMetaClass:
        """Tangent plus -1/(2 C1) times the pressure mass matrix in the pressure block.

        The preconditioning matrix of the iterative solver: its pressure block
        approximates the Schur complement -B A⁻¹ Bᵀ (spectrally equivalent to the
        pressure mass matrix over the shear modulus μ = 2 C1 for a stable
        Taylor–Hood pair). Compiled on first use only.
        """
        if not self.mixed:
            return self.tangent
        if self._preconditioner is None:
            dp = ufl.split(self._trial)[1]
            q = ufl.split(self._test)[1]
            mass = -(0.5 / self.material.local_C1) * dp * q * self.dx
            self._preconditioner = fem.form(self._tangent_ufl + mass)
        return self._preconditioner

    # -- set-up ---------------------------------------------------------------------------
    def _dirichlet_bcs(self) -> list[Any]:
        fdim = self.mesh.topology.dim - 1
        bcs = []
        for boundary, comps in self.fixed.items():
            facets = boundary_facets(self.facet_tags, [boundary])
            disp = self.W.sub(0) if self.mixed else self.W
            for c in comps:
                sub = disp.sub(c)
                collapsed, _ = sub.collapse()
                zero = fem.Function(collapsed)
                dofs = fem.locate_dofs_topological((sub, collapsed), fdim, facets)
                bcs.append(fem.dirichletbc(zero, dofs, sub))
        return bcs

    @staticmethod
    def _quadrature_points(degree: int) -> np.ndarray:
        import basix

        points, _ = basix.make_quadrature(basix.CellType.tetrahedron, max(degree, 1))
        return points

    # -- geometry -------------------------------------------------------------------------------
    def set_geometry(self, x: np.ndarray) -> None:
        """Move the mesh's geometry nodes to ``x`` (the reference configuration of the next solve).

        The compiled forms read the coordinates at assembly, so nothing is rebuilt; the
        reference volume is measured again, and the self-contact's skin rebuilt on the new
        coordinates. The contact zone stays the one found at set-up.
        """
        self.mesh.geometry.x[:] = x
        self.geometry_version += 1
        self._volume = self._measure_volume()
        if self.self_contact is not None:
            self.self_contact = self._self_contact_assembler(self.self_contact.settings)

    def _measure_volume(self) -> float:
        """|Ω| of the mesh's current geometry, m³."""
        return self.mesh.comm.allreduce(fem.assemble_scalar(self._volume_form), op=MPI.SUM)

    # -- case parameters ----------------------------------------------------------------------
    def set_case(self, material: Material, gravity: Gravity) -> None:
        """Set C1 and the (full) gravity load of a case; the load fraction starts at 0."""
        self.C1.value = material.C1
        self.density = material.density
        if self.self_contact is not None:
            self.self_contact.reset_counters()
        self.gravity = gravity.vector
        self.set_load_fraction(0.0)

    def set_load_fraction(self, fraction: float) -> None:
        """Scale the body force to ``fraction`` of ρ g."""
        self.body_force.value[:] = fraction * self.density * self.gravity

    # -- state ----------------------------------------------------------------------------------
    def displacement(self) -> fem.Function:
        """The displacement as a function on its own (collapsed) space."""
        if not self.mixed:
            return self.w
        u = self.w.sub(0).collapse()
        u.name = "displacement"
        return u

    def pressure(self) -> fem.Function | None:
        """The pressure field (Taylor–Hood only)."""
        if not self.mixed:
            return None
        p = self.w.sub(1).collapse()
        p.name = "pressure"
        return p

    def min_detF(self) -> float:
        """Smallest det F over all quadrature points of all cells (MPI-global)."""
        values = self._detF.eval(self._cells)
        local = float(np.min(values)) if values.size else np.inf
        return self.mesh.comm.allreduce(local, op=MPI.MIN)

    def contact_status(self) -> dict[str, Any] | None:
        """The contact force, and the skin vertices in the contact zone, touching, penetrating.

        None without contact. ``force_N`` is the contact pressure integrated over the
        reference skin (N; compare the breast's weight, ρ g times its volume); vertex
        counts and the deepest penetration (the penalty's slack, about the contact
        pressure over κ) are measured at the mesh vertices. MPI-global.
        """
        if self.contact is None:
            return None
        mesh = self.mesh
        u = self.displacement()
        dofs = node_to_vertex_dof(mesh, u.function_space)[self._contact_nodes]
        x = mesh.geometry.x[self._contact_nodes] + u.x.array.reshape(-1, 3)[dofs]
        gap = self.contact.obstacle.gap_values(x)
        comm = mesh.comm
        force = comm.allreduce(fem.assemble_scalar(self._contact_force), op=MPI.SUM)
        penetration = max(0.0, -float(gap.min(initial=0.0)))
        return {
            "force_N": float(force),
            "vertices": comm.allreduce(int(gap.size), op=MPI.SUM),
            "vertices_in_contact": comm.allreduce(int(np.sum(gap <= 0)), op=MPI.SUM),
            "max_penetration_mm": 1e3 * comm.allreduce(penetration, op=MPI.MAX),
        }

    def volume_change(self) -> float:
        """(∫ J dX - |Ω|) / |Ω|: zero for an exactly incompressible solution."""
        change = self.mesh.comm.allreduce(fem.assemble_scalar(self._volume_change), op=MPI.SUM)
        return change / self._volume

    @property
    def volume(self) -> float:
        """Reference volume |Ω| in m³."""
        return self._volume

    def num_dofs(self) -> int:
        """Global number of unknowns."""
        im = self.W.dofmap.index_map
        return im.size_global * self.W.dofmap.index_map_bs
