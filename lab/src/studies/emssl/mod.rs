//! The EMSSL paper's studies: Table II (every method in two joint ranges, the unit engine the
//! others build on), Table III and Figure 7 (sampling speed), Table IV (fast adaptation),
//! Figure 6 (the learning curve), and beyond it the seed spread and what limits EMSSL.

pub mod adaptation;
pub mod learning_curve;
pub mod sampling_speed;
pub mod seeds;
pub mod study;
pub mod table2;
