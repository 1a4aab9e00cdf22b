fn main() {
    match voyage_core::phantom::colon::anatomy_report(false) {
        Ok(s) => print!("{s}"),
        Err(e) => eprintln!("{e}"),
    }
}
