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
fn lorenz_refuses_more_than_six_joints() {
    assert!(lorenz(10, &[[-1.0, 1.0]; 7]).is_err());
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
    let g = grid(10_000, &r, 9.0, 0).unwrap();
    assert_eq!(g.len(), 21 * 21);
    assert_eq!(g[0], vec![-90.0, -90.0]);
    assert_eq!(g[1], vec![-90.0, -81.0]);
    assert_eq!(g[g.len() - 1], vec![90.0, 90.0]);
    let sub = grid(100, &r, 9.0, 0).unwrap();
    assert_eq!(sub.len(), 100);
    assert!(sub.iter().all(|q| g.contains(q)));
    assert!(grid(10, &r, 0.0, 0).is_err());
}
