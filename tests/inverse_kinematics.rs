//! Learned inverse kinematics: data, normalisation and error statistics.

use selfmodel::ik_data::{DistanceErrors, IkData, IkDataConfig, reach_errors};

#[test]
fn ik_data_is_seeded_split_and_normalised_both_ways() {
    let robot = selfmodel::dh_robot::ur5([-1.0, 1.0]);
    let cfg = IkDataConfig {
        samples: 500,
        train: 350,
        range_deg: 90.0,
        seed: 3,
    };
    let a = IkData::generate(&robot.chain, &cfg).unwrap();
    let b = IkData::generate(&robot.chain, &cfg).unwrap();
    assert_eq!(a.joints, b.joints);
    assert_eq!((a.train().len(), a.test().len()), (350, 150));
    let r = 90f64.to_radians();
    assert!(a.joints.iter().flatten().all(|&q| (-r..=r).contains(&q)));
    // Normalised training positions lie in [0, 1]; joints round-trip.
    for (q, p) in a.joints.iter().zip(&a.positions).take(350) {
        assert!(
            a.normalise_position(p)
                .iter()
                .all(|&v| (-1e-6..=1.0 + 1e-6).contains(&v))
        );
        let back = a.joints_from_normalised(&a.normalise_joints(q));
        assert!(back.iter().zip(q).all(|(x, y)| (x - y).abs() < 1e-5));
    }
    // The data's own joints reach their positions exactly.
    let e = reach_errors(&robot.chain, &a.positions, &a.joints);
    assert!(e.iter().all(|&v| v < 1e-12));
    assert!(IkData::generate(&robot.chain, &IkDataConfig { train: 500, ..cfg }).is_err());
}

#[test]
fn distance_error_statistics_are_in_centimetres() {
    let e = DistanceErrors::from_metres(&[0.01, 0.02, 0.03, 0.04, 0.10]);
    assert!((e.mean_cm - 4.0).abs() < 1e-9);
    assert!((e.median_cm - 3.0).abs() < 1e-9);
    assert!((e.max_cm - 10.0).abs() < 1e-9);
    assert_eq!(e.targets, 5);
}
