//! Results are data: CSV rows and the Markdown tables made from them, figures (plotters) and
//! image previews, behind the `figures` feature (the lab's). Nothing here is typed by hand.

#[cfg(feature = "figures")]
pub mod canvas;
#[cfg(feature = "figures")]
pub mod dataset_preview;
#[cfg(feature = "figures")]
pub mod figures;
pub mod table;
