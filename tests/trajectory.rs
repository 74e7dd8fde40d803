//! Joint samplers.

use selfmodel::sim::trajectory::{babbling, grid, lorenz};

#[test]
fn lorenz_first_sample_matches_the_paper() {
    let q = lorenz(3, &[[-90.0, 90.0]; 4]).unwrap();
    let want = [2.2778, 2.8339, 2.0153, 1.9446];
    for (a, b) in q[0].iter().zip(want) {
        assert!(
            (a - b).abs() < 5e-5,
            "first sample {:?}, expected {want:?}",
            q[0]
        );
    }
    // Smooth: consecutive samples differ by far less than the range.
    let q = lorenz(2000, &[[-90.0, 90.0]; 4]).unwrap();
    for w in q.windows(2) {
        for j in 0..4 {
            assert!((w[1][j] - w[0][j]).abs() < 10.0);
        }
    }
    assert!(q.iter().flatten().all(|v| v.abs() < 90.0));
}

#[test]
fn lorenz_drives_any_number_of_joints_within_asymmetric_limits() {
    // Seven joints with the Panda's limits (degrees), and a 10-joint robot.
    let panda = [
        [-166.0, 166.0],
        [-101.0, 101.0],
        [-166.0, 166.0],
        [-176.0, -4.0],
        [-166.0, 166.0],
        [-1.0, 215.0],
        [-166.0, 166.0],
    ];
    let q = lorenz(2000, &panda).unwrap();
    for row in &q {
        assert_eq!(row.len(), 7);
        for (v, r) in row.iter().zip(&panda) {
            assert!(*v > r[0] && *v < r[1], "{v} outside {r:?}");
        }
    }
    // The first four joints are the paper's channels, whatever the joint count.
    let four = lorenz(2000, &[[-90.0, 90.0]; 4]).unwrap();
    let ten = lorenz(2000, &[[-90.0, 90.0]; 10]).unwrap();
    assert!(four.iter().zip(&ten).all(|(a, b)| a[..] == b[..4]));
    // No two joints move alike: every pair of columns differs somewhere by 10 degrees.
    for a in 0..10 {
        for b in a + 1..10 {
            assert!(
                ten.iter().any(|q| (q[a] - q[b]).abs() > 10.0),
                "joints {a} and {b} move together"
            );
        }
    }
    // Each joint covers much of its range.
    for j in 0..10 {
        let (lo, hi) = ten
            .iter()
            .fold((f64::MAX, f64::MIN), |(l, h), q| (l.min(q[j]), h.max(q[j])));
        assert!(hi - lo > 60.0, "joint {j} spans only {lo}..{hi}");
    }
}

#[test]
fn babbling_is_seeded_and_within_range() {
    let r = [[-90.0, 90.0], [-10.0, 20.0]];
    let a = babbling(500, &r, 3);
    assert_eq!(a, babbling(500, &r, 3));
    assert_ne!(a, babbling(500, &r, 4));
    assert!(
        a.iter()
            .all(|q| q[0].abs() <= 90.0 && (-10.0..=20.0).contains(&q[1]))
    );
    let mean: f64 = a.iter().map(|q| q[0]).sum::<f64>() / 500.0;
    assert!(
        mean.abs() < 10.0,
        "uniform samples should centre near 0, got {mean}"
    );
}

#[test]
fn grid_has_nine_degree_steps() {
    let r = [[-90.0, 90.0]; 2];
    let g = grid(10_000, &r, &[9.0; 2], 0).unwrap();
    assert_eq!(g.len(), 21 * 21);
    assert_eq!(g[0], vec![-90.0, -90.0]);
    assert_eq!(g[1], vec![-90.0, -81.0]);
    assert_eq!(g[g.len() - 1], vec![90.0, 90.0]);
    let sub = grid(100, &r, &[9.0; 2], 0).unwrap();
    assert_eq!(sub.len(), 100);
    assert!(sub.iter().all(|q| g.contains(q)));
    assert!(grid(10, &r, &[0.0; 2], 0).is_err());
}

/// The Lorenz sampler stays finite and within the ranges for any joint count (it wrote NaN
/// angles past ~377 joints, where each further trajectory's step grew with its index).
#[test]
fn lorenz_stays_finite_for_a_thousand_joints() {
    let ranges = vec![[-90.0, 90.0]; 1000];
    let rows = selfmodel::sim::trajectory::lorenz(200, &ranges).unwrap();
    assert_eq!(rows.len(), 200);
    for row in &rows {
        assert_eq!(row.len(), 1000);
        assert!(
            row.iter().all(|v| v.is_finite() && v.abs() <= 90.0),
            "{row:?}"
        );
    }
}
