#![no_main]
//! MetaImage (.mha) and NRRD (.nrrd): text headers with attached data.
mod common;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, body)) = data.split_first() else { return };
    common::load_as(if pick & 1 == 0 { "input.mha" } else { "input.nrrd" }, body);
});
