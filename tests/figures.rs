//! Figures: clean log axes (one label per tick, across the whole range) and Pareto labels
//! that never overprint each other.

mod common;

use selfmodel::report::figures::{ParetoPoint, log_ticks, pareto_plot, tick_label};

#[test]
fn log_ticks_label_every_tick_once_across_the_range() {
    let t = log_ticks(0.8, 40.0);
    assert_eq!(t, vec![1.0, 2.0, 5.0, 10.0, 20.0]);
    let labels: Vec<String> = t.iter().map(|&v| tick_label(v)).collect();
    assert_eq!(labels, ["1", "2", "5", "10", "20"]);
    // Wider ranges thin out to 1-3, then to decades, and still span the range.
    let wide = log_ticks(0.5, 3.0e6);
    assert_eq!(wide.first(), Some(&1.0));
    assert_eq!(wide.last(), Some(&1.0e6));
    assert!(wide.len() <= 8, "{wide:?}");
    assert_eq!(tick_label(0.02), "0.02");
    assert!(log_ticks(0.0, 1.0).is_empty());
    // Under half a decade: more than one labelled tick.
    assert_eq!(log_ticks(0.045, 0.07).len(), 3);
}

#[test]
fn a_crowded_pareto_plot_is_drawn() {
    // Eight points on top of each other: the plot must still be written (labels that find no
    // free place are numbered in a key instead of overprinting).
    let points: Vec<ParetoPoint> = (0..8)
        .map(|i| ParetoPoint {
            label: format!("model number {i}"),
            fps: 10.0 + i as f64 * 0.01,
            quality: 20.0 + i as f64 * 0.001,
            reference: i % 2 == 1,
        })
        .collect();
    let tmp = common::tempdir();
    let path = tmp.path().join("selfmodel_pareto.png");
    pareto_plot(&path, "crowded", "PSNR", &points, &[("floor".into(), 19.0)]).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert!(bytes.starts_with(b"\x89PNG"));
}
