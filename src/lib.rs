//! multifit: multi-model, multi-type geometric fitting by learned point embeddings.
//!
//! An implementation of "Learning for Multi-Model and Multi-Type Fitting" (Xu, Cheong, Li).
//! A CNe-style network ([`model`]) maps every point of a set to a unit embedding; k-means
//! ([`cluster`]) groups the embeddings and picks the number of structures. [`loss`] holds the
//! training losses, [`data`] inputs, normalisation and datasets, [`metrics`] the evaluation
//! measures, [`registry`] model directories and the fit pipeline, [`train`] the trainer and
//! [`api`] the HTTP service; [`threads`] bounds the threads one fit uses.
#![forbid(unsafe_code)]

pub mod api;
pub mod cluster;
pub mod data;
pub mod loss;
pub mod metrics;
pub mod model;
pub mod registry;
pub mod threads;
pub mod train;
