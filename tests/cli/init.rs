//! `robcal init` (issue 19): a commented setup that reads back as written.

use std::process::Command;

#[test]
fn init_writes_a_setup_that_loads_and_never_overwrites() {
    let dir = std::env::temp_dir().join(format!("robcal-init-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let urdf = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/kr270/kr270.urdf");
    let out = dir.join("setup.toml");
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_robcal"))
            .args(args)
            .output()
            .expect("run robcal")
    };
    let o = run(&[
        "init",
        "--urdf",
        urdf.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(
        text.contains("config,rep,marker,load_kg,a1,a2,a3,a4,a5,a6,x,y,z"),
        "{text}"
    );
    assert!(text.contains("\"a1\", \"a2\""), "{text}");
    // It loads as a job: the robot found, base and tip as the URDF's.
    let job = robcal::io::Job::load(&out).expect("the template loads");
    assert_eq!(job.robot.joint_names.len(), 6);
    assert_eq!(job.setup.tip_link.as_deref(), Some("tool0"));
    // Every commented-out key parses too once uncommented.
    let all: String = text
        .lines()
        .map(|l| match l.strip_prefix("# ") {
            Some(k)
                if k.starts_with("ignore_columns")
                    || k.starts_with("[load]")
                    || k.starts_with("com ")
                    || k.starts_with("gravity ") =>
            {
                k
            }
            _ => l,
        })
        .collect::<Vec<_>>()
        .join("\n");
    let s = robcal::io::Setup::parse(&all, "all.toml").expect("every key parses");
    assert!(s.load.is_some() && s.ignore_columns.is_empty());
    // Never over an existing file; a bad tip is one line.
    let o = run(&[
        "init",
        "--urdf",
        urdf.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("already exists"));
    let o = run(&["init", "--urdf", urdf.to_str().unwrap(), "--tip", "nowhere"]);
    assert_eq!(o.status.code(), Some(1));
    assert_eq!(String::from_utf8_lossy(&o.stderr).lines().count(), 1);
    let _ = std::fs::remove_dir_all(&dir);
}
