fn main() {
    println!("voyage");
}
