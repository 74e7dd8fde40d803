//! The experiments of both papers, one module per binary of the same name in `experiments/`
//! (the EMSSL paper's under `emssl`, the benchmarks under `bench`), the registry that lists
//! them (`registry`), what they share (`run`), and the documents generated from their
//! results (`docs`: the README, docs/, every results.md).

pub mod ablations;
pub mod bench;
pub mod body_from_image;
pub mod damage;
pub mod data_scale;
pub mod docs;
pub mod emssl;
pub mod mesh_fidelity;
pub mod models;
pub mod multiview;
pub mod pareto;
pub mod registry;
pub mod run;
pub mod scaling;
pub mod table1;
