use super::*;
use std::os::unix::fs::MetadataExt;

/// A fresh directory under the system's temporary directory, removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let p = std::env::temp_dir().join(format!("cdm-keys-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        Scratch(p)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[test]
fn a_new_team_has_owner_only_files_and_each_directory_names_its_role() {
    let t = Scratch::new("new");
    let dirs = new_team(&t.0, 2).unwrap();
    let names: Vec<_> = dirs
        .iter()
        .map(|d| d.file_name().unwrap().to_owned())
        .collect();
    assert_eq!(names, ["orchestrator", "host-1", "host-2"]);
    for d in dirs.iter().chain([&t.0.join("authority"), &t.0]) {
        assert_eq!(
            std::fs::metadata(d).unwrap().mode() & 0o777,
            0o700,
            "{}",
            d.display()
        );
        for f in std::fs::read_dir(d)
            .unwrap()
            .flatten()
            .filter(|e| e.path().is_file())
        {
            assert_eq!(
                f.metadata().unwrap().mode() & 0o777,
                0o600,
                "{}",
                f.path().display()
            );
        }
    }
    assert_eq!(KeyDir::open(&dirs[0]).unwrap().role, Holder::Orchestrator);
    assert_eq!(KeyDir::open(&dirs[2]).unwrap().role, Holder::Host(2));
    // The authority's key is never in a machine's directory.
    assert!(!dirs.iter().any(|d| d.join("ca.key").exists()));
}

#[test]
fn keys_are_never_overwritten() {
    let t = Scratch::new("again");
    new_team(&t.0, 1).unwrap();
    let before = std::fs::read(t.0.join("host-1/key.pem")).unwrap();
    assert!(matches!(new_team(&t.0, 1), Err(KeyDirError::Exists { .. })));
    assert_eq!(std::fs::read(t.0.join("host-1/key.pem")).unwrap(), before);
}

#[test]
fn add_host_signs_the_next_number_with_the_same_authority() {
    let t = Scratch::new("add");
    new_team(&t.0, 1).unwrap();
    let (k, dir) = add_host(&t.0).unwrap();
    assert_eq!(k, 2);
    assert_eq!(KeyDir::open(&dir).unwrap().role, Holder::Host(2));
    let ca = |d: &str| std::fs::read(t.0.join(d).join("ca.pem")).unwrap();
    assert_eq!(ca("host-2"), ca("orchestrator"));
    assert_eq!(add_host(&t.0).unwrap().0, 3);
}

#[test]
fn a_key_readable_by_others_is_refused_naming_the_file() {
    use std::os::unix::fs::PermissionsExt;
    let t = Scratch::new("mode");
    new_team(&t.0, 1).unwrap();
    let key = t.0.join("host-1/key.pem");
    std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o644)).unwrap();
    let e = KeyDir::open(&t.0.join("host-1")).unwrap_err();
    assert!(
        e.to_string().contains("host-1/key.pem") && e.to_string().contains("0644"),
        "{e}"
    );
}

#[test]
fn a_directory_or_file_others_can_write_or_read_is_refused_saying_which() {
    use std::os::unix::fs::PermissionsExt;
    let t = Scratch::new("dirmode");
    new_team(&t.0, 1).unwrap();
    let d = t.0.join("host-1");
    let chmod = |p: &Path, m: u32| std::fs::set_permissions(p, PermissionsExt::from_mode(m));
    for (mode, says) in [(0o703, "write"), (0o730, "write"), (0o755, "read")] {
        chmod(&d, mode).unwrap();
        let e = KeyDir::open(&d).unwrap_err().to_string();
        let want = format!("{}: mode {mode:04o} lets others {says} it", d.display());
        assert!(e.contains(&want) && e.contains("chmod 700"), "{e}");
    }
    chmod(&d, 0o700).unwrap();
    chmod(&d.join("ca.pem"), 0o646).unwrap();
    let e = KeyDir::open(&d).unwrap_err().to_string();
    assert!(e.contains("ca.pem: mode 0646 lets others write it"), "{e}");
}

#[test]
fn a_missing_or_foreign_certificate_is_named() {
    let t = Scratch::new("missing");
    let e = KeyDir::open(&t.0).unwrap_err();
    assert!(e.to_string().contains(&t.0.display().to_string()), "{e}");
    files::make_dir(&t.0).unwrap();
    let e = KeyDir::open(&t.0).unwrap_err();
    assert!(e.to_string().contains("ca.pem"), "{e}");
    std::fs::remove_dir(&t.0).unwrap();
    new_team(&t.0, 1).unwrap();
    // The authority's own certificate names no role.
    let d = t.0.join("host-1");
    std::fs::remove_file(d.join("cert.pem")).unwrap();
    std::fs::copy(t.0.join("authority/ca.pem"), d.join("cert.pem")).unwrap();
    let e = KeyDir::open(&d).unwrap_err();
    assert!(
        e.to_string().contains("cert.pem") && e.to_string().contains("authority"),
        "{e}"
    );
}

#[test]
fn common_names_round_trip_and_nothing_else_is_a_role() {
    for r in [Holder::Orchestrator, Holder::Host(1), Holder::Host(63)] {
        assert_eq!(Holder::from_common_name(&r.common_name()), Some(r));
    }
    for cn in [
        "cdm host 0",
        "cdm host 01",
        "cdm host x",
        "orchestrator",
        "cdm host  1",
    ] {
        assert_eq!(Holder::from_common_name(cn), None, "{cn}");
    }
}
