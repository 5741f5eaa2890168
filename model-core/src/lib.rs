#![doc = include_str!("../README.md")]
#![cfg_attr(not(any(test, feature = "std")), no_std)]

pub mod error;
pub mod math;
pub mod mechanics;

pub use error::ParamError;
