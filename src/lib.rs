//! multifit: multi-model, multi-type geometric fitting by learned point embeddings.
//!
//! An implementation of "Learning for Multi-Model and Multi-Type Fitting" (Xu, Cheong, Li),
//! with explicit geometric structures beyond the paper. A fit runs [`pipeline::fit`]:
//! normalise -> features -> embed -> cluster -> refine -> answer.
//!
//! | module | holds |
//! |---|---|
//! | [`pipeline`] | the fit, stage by stage, in order: start here |
//! | [`data`] | validated inputs (`PointSet`), normalisation, frames, features, datasets, generators |
//! | [`model`] | the CNe-style embedding network (burn) and its fused serving forward |
//! | [`cluster`] | k-means on embeddings and the choice of K (SOD, silhouette) |
//! | [`geometry`] | explicit models of one group: lines, conics, homographies, fundamental matrices, subspaces |
//! | [`refine`] | learned groups refined into structures, with outliers |
//! | [`registry`] | model directories: cards, loading, ensembles |
//! | [`render`] | SVG pictures of fits and training curves |
//! | [`loss`] | training losses |
//! | [`metrics`] | clustering scores (error under best matching, NMI) |
//! | [`train`] | training, evaluation, cross-validation |
//! | [`api`] | the HTTP service |
//! | [`threads`] | the thread pool one fit uses |
#![forbid(unsafe_code)]

pub mod api;
pub mod cluster;
pub mod data;
pub mod geometry;
pub mod loss;
pub mod metrics;
pub mod model;
pub mod pipeline;
pub mod refine;
pub mod registry;
pub mod render;
pub mod threads;
pub mod train;
