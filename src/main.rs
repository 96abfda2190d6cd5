fn main() -> std::process::ExitCode {
    quiet_wayland();
    supertoroid::cli::main()
}

/// The Vulkan loader's Wayland support looks for a compositor under `XDG_RUNTIME_DIR` and
/// prints an error when that is unset, as it is in containers and services, though no
/// window is ever opened. Pointing it at the temporary directory finds no compositor,
/// quietly.
fn quiet_wayland() {
    let usable =
        std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|d| std::path::Path::new(&d).is_dir());
    if !usable {
        // SAFETY: first thing in main, before any other thread exists
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir()) };
    }
}
