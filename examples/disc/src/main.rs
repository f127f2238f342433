fn main() {
    eprintln!("fogray-disc: the disc experiment is not built yet");
    std::process::exit(1);
}
