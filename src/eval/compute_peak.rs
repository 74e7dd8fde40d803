//! The arithmetic peak of this machine, to say how close a workload comes to what the hardware
//! can do: the theoretical single-precision rate from the CPU's cores, clock and vector units,
//! and the rate a large matrix product reaches on the same burn backend.

use burn::tensor::{Device, Distribution, Tensor};

/// What this CPU can do in single precision.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CpuPeak {
    pub model: String,
    /// Cores the process may use.
    pub cores: usize,
    /// The clock /proc/cpuinfo reports (a virtual machine reports its nominal clock; boost
    /// clocks can be higher).
    pub ghz: f64,
    /// f32 floating-point operations per cycle per core (a fused multiply-add counts two),
    /// from the vector units the flags announce; see [`flops_per_cycle`].
    pub flops_per_cycle: f64,
    pub vector_units: String,
    /// `cores * ghz * flops_per_cycle`, GFLOP/s.
    pub theoretical_gflops: f64,
}

/// f32 FLOP per cycle per core and a description, from `/proc/cpuinfo`'s vendor, family and
/// flags: two fused multiply-add pipes of the widest vector width the flags announce (AVX-512
/// 16 lanes, AVX2 8, SSE 4), times two operations each. AMD's Zen 4 (family 25) runs AVX-512
/// on 256-bit pipes, so it counts as 8 lanes.
pub fn flops_per_cycle(vendor: &str, family: u32, flags: &[&str]) -> (f64, String) {
    let has = |f: &str| flags.contains(&f);
    let (lanes, what) = if has("avx512f") && !(vendor == "AuthenticAMD" && family == 25) {
        (16.0, "AVX-512, two 512-bit FMA pipes")
    } else if has("avx512f") {
        (8.0, "AVX-512 on two 256-bit FMA pipes (Zen 4)")
    } else if has("avx2") && has("fma") {
        (8.0, "AVX2, two 256-bit FMA pipes")
    } else {
        (4.0, "SSE, two 128-bit pipes (assumed)")
    };
    (2.0 * lanes * 2.0, what.to_string())
}

/// This machine in words for a report: "2 cores of MODEL", with its vector units when
/// `vector_units`; "an unknown CPU" where `/proc/cpuinfo` cannot tell.
pub fn machine_label(vector_units: bool) -> String {
    CpuPeak::detect().map_or_else(
        || "an unknown CPU".into(),
        |c| match vector_units {
            true => format!("{} cores of {} ({})", c.cores, c.model, c.vector_units),
            false => format!("{} cores of {}", c.cores, c.model),
        },
    )
}

impl CpuPeak {
    /// Read `/proc/cpuinfo` (Linux); `None` elsewhere or when it lacks what is needed.
    pub fn detect() -> Option<Self> {
        let text = std::fs::read_to_string("/proc/cpuinfo").ok()?;
        let field = |name: &str| {
            text.lines()
                .find(|l| l.split(':').next().is_some_and(|k| k.trim() == name))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        };
        let ghz = field("cpu MHz")?.parse::<f64>().ok()? / 1000.0;
        let flags_line = field("flags").unwrap_or_default();
        let flags: Vec<&str> = flags_line.split_whitespace().collect();
        let vendor = field("vendor_id").unwrap_or_default();
        let family = field("cpu family")
            .and_then(|f| f.parse().ok())
            .unwrap_or(0);
        let (per_cycle, what) = flops_per_cycle(&vendor, family, &flags);
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        Some(CpuPeak {
            model: field("model name").unwrap_or_else(|| "unknown".into()),
            cores,
            ghz,
            flops_per_cycle: per_cycle,
            vector_units: format!("{what} (family {family})"),
            theoretical_gflops: cores as f64 * ghz * per_cycle,
        })
    }
}

/// GFLOP/s of an `n x n` by `n x n` f32 matrix product on `device`: one warm-up, then the
/// median of `repeats` (the result is read back, so the time includes finishing the work).
pub fn matmul_gflops(device: &Device, n: usize, repeats: usize) -> f64 {
    let (a, b): (Tensor<2>, Tensor<2>) = crate::core::device::with_seed(device, 0, || {
        (
            Tensor::random([n, n], Distribution::Default, device),
            Tensor::random([n, n], Distribution::Default, device),
        )
    });
    let seconds = crate::core::timing::median_seconds(
        crate::core::timing::Repeats::exactly(1, repeats),
        || {
            let c = a.clone().matmul(b.clone());
            let _ = c.into_data();
        },
    );
    2.0 * (n as f64).powi(3) / seconds / 1e9
}

/// GB/s of an elementwise pass over `n` f32 values on `device` (each read once and written
/// once: `8 n` bytes): one warm-up, then the median of `repeats`, each synchronised with the
/// device. The bandwidth a memory-bound kernel can reach there.
pub fn bandwidth_gbytes(device: &Device, n: usize, repeats: usize) -> f64 {
    let x: Tensor<1> = crate::core::device::with_seed(device, 0, || {
        Tensor::random([n], Distribution::Default, device)
    });
    let seconds = crate::core::timing::median_seconds(
        crate::core::timing::Repeats::exactly(1, repeats),
        || {
            let y = x.clone().add_scalar(1.0);
            let _ = device.sync();
            drop(y);
        },
    );
    8.0 * n as f64 / seconds / 1e9
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_vector_width_follows_the_flags() {
        assert_eq!(
            flops_per_cycle("AuthenticAMD", 26, &["avx2", "fma", "avx512f"]).0,
            64.0
        );
        assert_eq!(
            flops_per_cycle("AuthenticAMD", 25, &["avx2", "fma", "avx512f"]).0,
            32.0
        );
        assert_eq!(flops_per_cycle("GenuineIntel", 6, &["avx2", "fma"]).0, 32.0);
        assert_eq!(flops_per_cycle("GenuineIntel", 6, &["sse2"]).0, 16.0);
    }
}
