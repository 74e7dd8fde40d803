//! The one device-selection function.

use burn::tensor::Tensor;
use selfmodel::core::device::{DeviceChoice, available, select};

#[test]
fn cpu_device_runs_a_tensor_op() {
    assert!(available().contains(&DeviceChoice::Cpu));
    let dev = select(DeviceChoice::Cpu).unwrap();
    let t = Tensor::<1>::from_floats([1.0, 2.0, 3.0], &dev);
    let s: f32 = t.sum().into_scalar();
    assert_eq!(s, 6.0);
}

#[test]
fn a_backend_not_compiled_in_is_a_clear_error() {
    if cfg!(feature = "ndarray") {
        return;
    }
    let err = select(DeviceChoice::Ndarray).unwrap_err().to_string();
    assert!(err.contains("cargo feature `ndarray`"), "{err}");
}
