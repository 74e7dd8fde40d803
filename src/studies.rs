//! The experiments of both papers, one module per binary of the same name in `experiments/`,
//! the registry that lists them (`registry`), what they share (`run`), and the documents
//! generated from their results (`docs`: the README, docs/, every results.md).

pub mod ablations;
pub mod bench_decoders;
pub mod bench_ffksm_step;
pub mod bench_ik;
pub mod body_from_image;
pub mod damage;
pub mod device_equivalence;
pub mod docs;
pub mod emssl;
pub mod gpu_check;
pub mod mesh_fidelity;
pub mod multiview;
pub mod registry;
pub mod run;
pub mod table1;
