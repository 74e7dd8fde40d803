//! The EMSSL paper's methods and what its tables run: Table II's unit ([`method::IkMethod`])
//! and its methods, direct regression ([`direct_regression`]), EMSSL ([`emssl`]), distal
//! supervised learning ([`distal_learning`]), a conditional GAN ([`cgan`]), and beyond the
//! paper the flow ([`flow_method`]) and damped least squares from home ([`dls_from_home`]);
//! EMSSL's batched sampling pass (Table III, [`sampling_pass`]) and link calibration (Table IV,
//! [`calibration`]). The studies that run them are the lab's (`studies::emssl`).

pub mod calibration;
pub mod cgan;
pub mod direct_regression;
pub mod distal_learning;
pub mod dls_from_home;
pub mod emssl;
pub mod flow_method;
pub mod method;
pub mod sampling_pass;
