//! The deployment files as a cluster and compose take them: the Kubernetes manifests
//! (`deploy/kubernetes/`) validated against the Kubernetes schemas by
//! `kubernetes-validate` (PyPI; `.ci/run` installs it), strictly, so an unknown field
//! fails; and the Dockerfile's dependency layer, whose placeholder sources must satisfy
//! every target Cargo.toml names.

use std::path::{Path, PathBuf};
use std::process::Command;

fn manifests() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("deploy/kubernetes");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "yaml"))
        .collect();
    files.sort();
    files
}

/// `kubernetes-validate --strict` on `files`: its exit status and output. A missing tool
/// fails the test, saying how to install it.
fn validate(files: &[PathBuf]) -> (bool, String) {
    let out = Command::new("kubernetes-validate")
        .arg("--strict")
        .args(files)
        .output()
        .unwrap_or_else(|e| {
            panic!("kubernetes-validate not found ({e}): pip install kubernetes-validate")
        });
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr),
    )
}

#[test]
fn the_kubernetes_manifests_validate_against_the_schemas() {
    let files = manifests();
    let names: Vec<String> = files
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    for kind in [
        "deployment.yaml",
        "deployment-gpu.yaml",
        "service.yaml",
        "hpa.yaml",
    ] {
        assert!(names.iter().any(|n| n == kind), "no {kind} in {names:?}");
    }
    let (ok, output) = validate(&files);
    assert!(ok, "{output}");
    assert_eq!(output.matches("passed").count(), files.len(), "{output}");
    // the probes are the service's own routes, the GPU variant asks for a GPU
    let cpu =
        std::fs::read_to_string(&files[names.iter().position(|n| n == "deployment.yaml").unwrap()])
            .unwrap();
    assert!(cpu.contains("path: /readyz") && cpu.contains("path: /healthz"));
    let gpu = std::fs::read_to_string(
        &files[names
            .iter()
            .position(|n| n == "deployment-gpu.yaml")
            .unwrap()],
    )
    .unwrap();
    assert!(gpu.contains("nvidia.com/gpu: 1"));
}

#[test]
fn a_manifest_with_an_unknown_field_does_not_validate() {
    let dir = std::env::temp_dir().join(format!("supertoroid-deploy-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("service.yaml");
    let service = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("deploy/kubernetes/service.yaml"),
    )
    .unwrap();
    std::fs::write(&bad, service.replace("targetPort:", "targetPortt:")).unwrap();
    let (ok, output) = validate(&[bad]);
    assert!(!ok, "{output}");
    assert!(output.contains("targetPortt"), "{output}");
}

/// schemathesis (PyPI; `.ci/run` installs it) fuzzes the running service against its own
/// OpenAPI document (`scripts/api-fuzz`: 200 requests an operation from a fixed seed,
/// about 3,600 in all, half a minute): no 5xx, every response on its schema,
/// no undocumented status or content type, no schema-invalid request accepted, and no
/// request that keeps to the document refused for its form. A missing tool fails.
#[test]
fn the_service_keeps_to_its_openapi_document_under_schemathesis() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new(root.join("scripts/api-fuzz"))
        .arg("200")
        .env("SUPERTOROID_BIN", env!("CARGO_BIN_EXE_supertoroid"))
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{text}");
    assert!(text.contains("passed"), "{text}");
}

/// The Dockerfile builds the crates before the sources arrive, from placeholders that
/// `scripts/placeholder-sources` writes; cargo refuses the manifest if a `[[bench]]` it
/// names has no file, so the script is run here on a copy of the manifest and cargo asked
/// to read it (a target that does not exist: the answer names the targets it found).
#[test]
fn the_dockerfiles_placeholder_sources_satisfy_every_target_of_the_manifest() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dockerfile = std::fs::read_to_string(root.join("Dockerfile")).unwrap();
    assert!(
        dockerfile.contains("placeholder-sources &&"),
        "the Dockerfile no longer builds its dependency layer from scripts/placeholder-sources"
    );
    let dir = std::env::temp_dir().join(format!("supertoroid-placeholders-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for file in ["Cargo.toml", "Cargo.lock"] {
        std::fs::copy(root.join(file), dir.join(file)).unwrap();
    }
    let script = Command::new("sh")
        .arg(root.join("scripts/placeholder-sources"))
        .current_dir(&dir)
        .status()
        .unwrap();
    assert!(script.success());
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args(["build", "--offline", "--locked", "--bin", "no_such_target"])
        .current_dir(&dir)
        .env_remove("CARGO_TARGET_DIR")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(
        stderr.contains("no bin target named") && stderr.contains("supertoroid"),
        "cargo did not read the placeholder manifest:\n{stderr}"
    );
}
