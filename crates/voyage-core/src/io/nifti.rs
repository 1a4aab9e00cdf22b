//! NIfTI-1 (being written).
use std::path::Path;
use super::Loaded;
use crate::{Error, Result, Volume};
pub fn load(path: &Path) -> Result<Loaded> { Err(Error::format(path, "NIfTI not yet supported")) }
pub fn save_i16(path: &Path, _vol: &Volume<i16>) -> Result<()> { Err(Error::format(path, "NIfTI writing not yet supported")) }
