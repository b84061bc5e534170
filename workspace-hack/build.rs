// Cargo applies the build-dependencies' features only to a crate with a build script.
fn main() {}
