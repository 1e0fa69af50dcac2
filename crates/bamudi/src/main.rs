//! The `bamudi` command-line interface.
fn main() {
    println!("bamudi: not yet implemented");
}
