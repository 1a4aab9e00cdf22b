//! nrrd (being written).
use std::path::Path;
use super::Loaded;
use crate::{Error, Result};
pub fn load(path: &Path) -> Result<Loaded> { Err(Error::format(path, "nrrd not yet supported")) }
