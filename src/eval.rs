//! Measuring a trained model: image metrics, the self-model evaluation on held-out poses,
//! inference speed (warm-up, synchronised, median of repeats) and the machine's compute peak.

pub mod compute_peak;
#[cfg(feature = "cube")]
pub mod device_counts;
pub mod evaluation;
pub mod inference_speed;
pub mod metrics;
pub mod roofline;
