//! Inputs: validated point sets, normalisation, labelled datasets and synthetic generators.

pub mod dataset;
pub mod density;
pub mod features;
pub mod frames;
pub mod motion;
pub mod points;
pub mod ranges;
pub mod screen;
pub mod symmetry;
pub mod synthetic;
pub mod twoview;
pub mod visibility;

pub use dataset::{
    DataError, DataSource, Sample, Sequence, SequenceFile, SpecError, load_sequences, seeded_rng,
};
pub use points::{ImageSize, InputError, Kind, MIN_POINTS, Normalization, PointSet};
pub use symmetry::{Symmetry, with_symmetries};
pub use visibility::Visibility;
