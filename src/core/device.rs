//! The one place that names a burn backend.
//!
//! Model code is backend-agnostic (burn 0.22 tensors carry their backend in the `Device`
//! value); the binaries call [`select`] with the device a user chose and pass it on.

use burn::tensor::Device;

use crate::core::error::{Error, Result};

/// The `device` choices. Only those compiled in can be selected.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum DeviceChoice {
    /// burn's pure-Rust `flex` CPU backend (default feature `flex`).
    Cpu,
    /// burn-ndarray, deprecated and ~80x slower than flex here (feature `ndarray`).
    Ndarray,
    /// The best GPU wgpu finds (feature `wgpu`; `CUBECL_WGPU_DEFAULT_DEVICE=Cpu` for lavapipe).
    Wgpu,
    /// The first NVIDIA GPU, through burn's CUDA backend (feature `cuda`, built by
    /// `scripts/build_cuda.sh`; needs the NVIDIA driver at run time).
    Cuda,
}

impl std::fmt::Display for DeviceChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            DeviceChoice::Cpu => "cpu",
            DeviceChoice::Ndarray => "ndarray",
            DeviceChoice::Wgpu => "wgpu",
            DeviceChoice::Cuda => "cuda",
        })
    }
}

impl DeviceChoice {
    /// A GPU backend (wgpu or CUDA): our CubeCL kernels, lazy tensors, a device to synchronise.
    pub fn is_gpu(self) -> bool {
        matches!(self, DeviceChoice::Wgpu | DeviceChoice::Cuda)
    }

    /// The GPU backend this build runs first: CUDA where compiled in, else wgpu.
    pub fn gpu() -> DeviceChoice {
        if cfg!(feature = "cuda") {
            DeviceChoice::Cuda
        } else {
            DeviceChoice::Wgpu
        }
    }
}

/// The choices compiled into this binary, in order of preference.
pub fn available() -> Vec<DeviceChoice> {
    let mut v = Vec::new();
    if cfg!(feature = "flex") {
        v.push(DeviceChoice::Cpu);
    }
    if cfg!(feature = "cuda") {
        v.push(DeviceChoice::Cuda);
    }
    if cfg!(feature = "wgpu") {
        v.push(DeviceChoice::Wgpu);
    }
    if cfg!(feature = "ndarray") {
        v.push(DeviceChoice::Ndarray);
    }
    v
}

/// Build the burn device for a `device` choice, or say which features to enable.
pub fn select(choice: DeviceChoice) -> Result<Device> {
    // The kernels run on rayon's workers: subnormals flushed there (core::denormals).
    crate::core::denormals::flush_in_workers();
    let missing = |feature: &str| {
        Error::Device(format!(
            "`device` {choice} is not compiled in: rebuild with the cargo feature `{feature}` (compiled in: {})",
            available()
                .iter()
                .map(|c| c.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ))
    };
    match choice {
        DeviceChoice::Cpu => {
            #[cfg(feature = "flex")]
            return Ok(Device::flex());
            #[cfg(not(feature = "flex"))]
            return Err(missing("flex"));
        }
        DeviceChoice::Ndarray => {
            #[cfg(feature = "ndarray")]
            #[allow(deprecated)]
            return Ok(Device::ndarray());
            #[cfg(not(feature = "ndarray"))]
            return Err(missing("ndarray"));
        }
        DeviceChoice::Wgpu => {
            #[cfg(feature = "wgpu")]
            return Ok(Device::wgpu(burn::tensor::DeviceKind::DefaultDevice));
            #[cfg(not(feature = "wgpu"))]
            return Err(missing("wgpu"));
        }
        DeviceChoice::Cuda => {
            #[cfg(feature = "cuda")]
            return cuda_driver().map(|()| Device::cuda(0));
            #[cfg(not(feature = "cuda"))]
            return Err(missing("cuda"));
        }
    }
}

/// The NVIDIA driver's library, loaded as cudarc loads it: without it, burn's CUDA backend
/// panics on its device thread at the first operation; here it is one line at the edge.
#[cfg(feature = "cuda")]
fn cuda_driver() -> Result<()> {
    let loads = |name: &std::ffi::CStr| {
        // SAFETY: dlopen with a valid C string; the handle is closed at once (cudarc opens the
        // library again for itself).
        unsafe {
            let handle = libc::dlopen(name.as_ptr(), libc::RTLD_LAZY);
            if !handle.is_null() {
                libc::dlclose(handle);
            }
            !handle.is_null()
        }
    };
    if loads(c"libcuda.so.1") || loads(c"libcuda.so") {
        Ok(())
    } else {
        Err(Error::Device(
            "`device` cuda: no NVIDIA driver here (libcuda.so.1 cannot be loaded; LD_LIBRARY_PATH names where it is): run on a machine with an NVIDIA GPU, or use `device` wgpu or cpu".into(),
        ))
    }
}

/// Serialises seeding and drawing from the backend's random generator, which is global to
/// the backend (one per process), not to a device value.
static RNG: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Seed `device`'s random generator and run `draw` while no other thread can draw from it:
/// every random tensor the library makes is drawn through here or [`seeded`].
pub fn with_seed<T>(device: &Device, seed: u64, draw: impl FnOnce() -> T) -> T {
    let _only_us = RNG.lock().unwrap_or_else(|e| e.into_inner());
    device.seed(seed);
    draw()
}

/// Build a module with `build` and draw all its parameters under [`with_seed`], so the same
/// seed gives the same model whatever else the process is doing (tests run in parallel
/// threads). burn initialises parameters lazily, on first use, so every parameter is
/// touched here before the generator is released.
///
/// The parameters are drawn on the CPU (`flex`, when compiled in) and then moved to `device`:
/// each backend has its own generator, and this way a model trained on a GPU starts from the
/// very numbers it starts from on the CPU (`--device wgpu` is compared with the CPU from the
/// same seed in `tests/gpu/equivalence.rs`).
pub fn seeded<M: burn::module::Module>(
    device: &Device,
    seed: u64,
    build: impl FnOnce(&Device) -> M,
) -> M {
    struct Touch;
    impl burn::module::ModuleVisitor for Touch {
        fn visit_float<const D: usize>(
            &mut self,
            param: &burn::module::Param<burn::tensor::Tensor<D>>,
        ) {
            let _ = param.val();
        }
    }
    let home = draw_device(device);
    let module = with_seed(&home, seed, || {
        let module = build(&home);
        module.visit(&mut Touch);
        module
    });
    if &home == device {
        module
    } else {
        // `fork`, not `to_device`: the parameters start a graph of their own there (moved,
        // they would stay tied to the CPU's tape).
        module.fork(device)
    }
}

/// Where [`seeded`] draws parameters for `device`: the CPU backend, with autodiff when
/// `device` has it.
fn draw_device(device: &Device) -> Device {
    #[cfg(feature = "flex")]
    {
        let cpu = Device::flex();
        if device.is_autodiff() {
            cpu.autodiff()
        } else {
            cpu
        }
    }
    #[cfg(not(feature = "flex"))]
    device.clone()
}
