#![no_main]
//! NIfTI-1, raw (.nii) and gzipped (.nii.gz): the first byte picks which, the rest is the file.
mod common;
use std::io::Write;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, body)) = data.split_first() else { return };
    if pick & 1 == 0 {
        common::load_as("input.nii", body);
    } else {
        // Gzip the input so the fuzzer explores headers behind the decompressor too.
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        gz.write_all(body).expect("gzip in memory");
        common::load_as("input.nii.gz", &gz.finish().expect("gzip in memory"));
    }
});
