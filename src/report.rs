//! Results are data: CSV rows and the Markdown tables made from them, figures (plotters) and
//! image previews. Nothing here is typed by hand.

pub mod canvas;
pub mod dataset_preview;
pub mod figures;
pub mod table;
