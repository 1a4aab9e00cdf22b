//! DICOM series and file loading (being written).
use std::path::Path;
use super::{Loaded, LoadOptions};
use crate::{Error, Result};
pub fn load_dir(path: &Path, _opts: &LoadOptions) -> Result<Loaded> { Err(Error::format(path, "DICOM folders not yet supported")) }
pub fn load_file(path: &Path, _opts: &LoadOptions) -> Result<Loaded> { Err(Error::format(path, "DICOM files not yet supported")) }
