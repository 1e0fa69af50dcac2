//! Shared helpers: small plate meshes and prescribed-displacement solves.
use mitergate::fe::shell::ShellMaterial;
use mitergate::fe::{QuadElement, ShellMesh, ShellModel, Support};

pub const STEEL: ShellMaterial = ShellMaterial {
    youngs_modulus: 29.0e6,
    poisson_ratio: 0.3,
};

/// Rectangular `nx x ny` mesh of `[0, a] x [0, b]` in the plane z = 0.
pub fn plate_mesh(a: f64, b: f64, nx: usize, ny: usize, t: f64) -> ShellMesh {
    let mut nodes = vec![];
    for j in 0..=ny {
        for i in 0..=nx {
            nodes.push([a * i as f64 / nx as f64, b * j as f64 / ny as f64, 0.0]);
        }
    }
    let id = |i: usize, j: usize| j * (nx + 1) + i;
    let mut elements = vec![];
    for j in 0..ny {
        for i in 0..nx {
            elements.push(QuadElement {
                nodes: [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)],
                thickness: t,
            });
        }
    }
    ShellMesh { nodes, elements }
}

/// The MacNeal–Harder distorted 5-element patch on `[0, 0.24] x [0, 0.12]`; nodes 0..4 are the
/// corners, 4..8 interior.
pub fn distorted_patch(t: f64) -> ShellMesh {
    let nodes = vec![
        [0.0, 0.0, 0.0],
        [0.24, 0.0, 0.0],
        [0.24, 0.12, 0.0],
        [0.0, 0.12, 0.0],
        [0.04, 0.02, 0.0],
        [0.18, 0.03, 0.0],
        [0.16, 0.08, 0.0],
        [0.08, 0.08, 0.0],
    ];
    let quads = [
        [0, 1, 5, 4],
        [1, 2, 6, 5],
        [2, 3, 7, 6],
        [3, 0, 4, 7],
        [4, 5, 6, 7],
    ];
    ShellMesh {
        nodes,
        elements: quads
            .iter()
            .map(|&n| QuadElement {
                nodes: n,
                thickness: t,
            })
            .collect(),
    }
}

/// Rotates a mesh rigidly (rows of `r` are the new axes) to test frame independence.
pub fn rotate(mesh: &ShellMesh, r: [[f64; 3]; 3]) -> ShellMesh {
    let mut m = mesh.clone();
    for p in &mut m.nodes {
        let q = *p;
        *p = std::array::from_fn(|i| (0..3).map(|k| r[k][i] * q[k]).sum());
    }
    m
}

/// Solves with all DOFs of `boundary` nodes prescribed to `exact(node)`; returns full `u`.
pub fn solve_prescribed(
    mesh: &ShellMesh,
    boundary: &[usize],
    exact: impl Fn([f64; 3]) -> [f64; 6],
) -> (ShellModel, Vec<f64>) {
    let supports: Vec<Support> = boundary
        .iter()
        .flat_map(|&node| (0..6).map(move |dof| Support::Fixed { node, dof }))
        .collect();
    let model = ShellModel::build(mesh.clone(), STEEL, 1e-3, supports).unwrap();
    let mut ub = vec![0.0; model.n_dofs()];
    for &n in boundary {
        let v = exact(mesh.nodes[n]);
        ub[6 * n..6 * n + 6].copy_from_slice(&v);
    }
    let f: Vec<f64> = model.apply_stiffness(&ub).iter().map(|v| -v).collect();
    let ui = model.solve(&f).unwrap();
    let u = ub.iter().zip(&ui).map(|(a, b)| a + b).collect();
    (model, u)
}
