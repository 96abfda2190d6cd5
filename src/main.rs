fn main() -> std::process::ExitCode {
    supertoroid::cli::main()
}
