//! Times phantom generation: `cargo run --release -p voyage-core --example phantom_time`.
use std::time::Instant;

use voyage_core::phantom::{self, ColonOptions};

fn main() -> Result<(), voyage_core::Error> {
    for (name, small) in [("small colon", true), ("full colon", false)] {
        let t = Instant::now();
        let p = phantom::colon(&ColonOptions { small, ..ColonOptions::default() })?;
        println!("{name}: {:.2} s ({} voxels)", t.elapsed().as_secs_f64(), p.ct.data().len());
    }
    let t = Instant::now();
    let p = phantom::pipe(1)?;
    println!("pipe: {:.2} s ({} voxels)", t.elapsed().as_secs_f64(), p.ct.data().len());
    Ok(())
}
