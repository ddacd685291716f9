//! Setup TOML (`robcal::io::setup`) and `Job::load`.

use std::path::{Path, PathBuf};

use robcal::io::{
    AngleUnit, ErrorKind, GeometryModel, Job, LengthUnit, Load, Marker, MarkerModel, Setup, Units,
};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures")
}

fn parse(text: &str) -> Result<Setup, robcal::io::InputError> {
    Setup::parse(text, "s.toml")
}

#[test]
fn defaults() {
    let s = parse("robot = \"r.urdf\"\n").unwrap();
    assert_eq!(s, Setup::new("r.urdf"));
    assert_eq!(s.base_link, None);
    assert_eq!(s.tip_link, None);
    assert_eq!(
        s.units,
        Units {
            angle: AngleUnit::Rad,
            length: LengthUnit::M
        }
    );
    assert_eq!(
        s.markers,
        [Marker {
            id: 1,
            xyz: [0.0; 3],
            link: None
        }]
    );
    assert_eq!(s.load, None);
    assert_eq!((s.noise.sigma0_um, s.noise.lambda), (10.0, 1.0));
    assert!(s.model.compliance.is_empty() && s.model.compliance_by_angle.is_empty());
    assert_eq!(s.model.geometry, GeometryModel::None);
    assert!(!s.model.base_frame);
    assert_eq!(s.model.markers, MarkerModel::Nominal);

    // Defaults inside tables that are present.
    let s =
        parse("robot = \"r.urdf\"\n[load]\n[[marker]]\nid = 4\n[noise]\nlambda = 0.5\n").unwrap();
    assert_eq!(
        s.load,
        Some(Load {
            com: [0.0; 3],
            gravity: [0.0, 0.0, -9.80665]
        })
    );
    assert_eq!(
        s.markers,
        [Marker {
            id: 4,
            xyz: [0.0; 3],
            link: None
        }]
    );
    assert_eq!((s.noise.sigma0_um, s.noise.lambda), (10.0, 0.5));
}

#[test]
fn every_key_of_the_contract() {
    let text = r#"
robot = "kr270.urdf"
base_link = "base_link"
tip_link = "flange"
[units]
angle = "deg"
length = "mm"
[[marker]]
id = 1
xyz = [0.0, 0.30, 0.20]
[[marker]]
id = 2
xyz = [0.1, 0.30, 0.20]
[load]
com = [0.25, 0.0, 0.30]
gravity = [0.0, 0.0, -9.81]
[noise]
sigma0_um = 10.0
lambda = 1.0
[model]
compliance = ["a2", "a3", "a4", "a5", "a6"]
compliance_by_angle = ["a2"]
geometry = "full"
base_frame = true
markers = "identify"
"#;
    let s = parse(text).unwrap();
    assert_eq!(s.base_link.as_deref(), Some("base_link"));
    assert_eq!(
        s.units,
        Units {
            angle: AngleUnit::Deg,
            length: LengthUnit::Mm
        }
    );
    assert_eq!(
        s.markers[1],
        Marker {
            id: 2,
            xyz: [0.1, 0.30, 0.20],
            link: None
        }
    );
    assert_eq!(s.load.unwrap().gravity, [0.0, 0.0, -9.81]);
    assert_eq!(s.model.compliance, ["a2", "a3", "a4", "a5", "a6"]);
    assert_eq!(s.model.geometry, GeometryModel::Full);
    assert!(s.model.base_frame);
    assert_eq!(s.model.markers, MarkerModel::Identify);
    // Written back and read again: the same setup.
    assert_eq!(parse(&s.to_toml()).unwrap(), s);
    assert_eq!(
        parse(&Setup::new("x.urdf").to_toml()).unwrap(),
        Setup::new("x.urdf")
    );
}

#[test]
fn unknown_keys_are_rejected_by_name() {
    for (text, key, line) in [
        ("robot = \"r\"\nrobt = 1\n", "robt", 2),
        ("robot = \"r\"\n[units]\nangel = \"deg\"\n", "angel", 3),
        (
            "robot = \"r\"\n[model]\ncompliances = []\n",
            "compliances",
            3,
        ),
        (
            "robot = \"r\"\n[[marker]]\nid = 1\nxyz = [0,0,0]\nname = \"m\"\n",
            "name",
            5,
        ),
        ("robot = \"r\"\n[noise]\nsigma = 3\n", "sigma", 3),
        ("robot = \"r\"\n[load]\nmass = 3\n", "mass", 3),
        ("robot = \"r\"\n[loads]\n", "loads", 2),
    ] {
        let e = parse(text).unwrap_err();
        assert_eq!(e.kind, ErrorKind::UnknownKey, "{e}");
        assert!(e.message.contains(&format!("`{key}`")), "{e}");
        assert_eq!(e.line, Some(line), "{e}");
        assert!(
            e.to_string()
                .starts_with(&format!("s.toml:{line}: unknown field `{key}`")),
            "{e}"
        );
    }
}

#[test]
fn bad_values_are_rejected() {
    let cases = [
        ("[units]\nangle = \"grad\"\n", ErrorKind::Syntax, "grad"),
        ("[model]\ngeometry = \"some\"\n", ErrorKind::Syntax, "some"),
        ("[model]\nmarkers = \"fit\"\n", ErrorKind::Syntax, "fit"),
        (
            "[[marker]]\nid = 1\n[[marker]]\nid = 1\n",
            ErrorKind::Duplicate,
            "marker[1].id",
        ),
        ("[[marker]]\nid = -1\n", ErrorKind::Syntax, ""),
        ("[[marker]]\nxyz = [0, 0, 0]\n", ErrorKind::Syntax, "id"),
        (
            "[[marker]]\nid = 1\nxyz = [0, nan, 0]\n",
            ErrorKind::NonFinite,
            "marker[0].xyz",
        ),
        (
            "[noise]\nsigma0_um = 0\n",
            ErrorKind::InvalidValue,
            "sigma0_um",
        ),
        ("[noise]\nlambda = -1\n", ErrorKind::InvalidValue, "lambda"),
        ("[noise]\nlambda = inf\n", ErrorKind::NonFinite, "lambda"),
        (
            "[load]\ngravity = [0, 0, inf]\n",
            ErrorKind::NonFinite,
            "load.gravity",
        ),
        (
            "[model]\ncompliance = [\"a\", \"a\"]\n",
            ErrorKind::Duplicate,
            "'a' listed twice",
        ),
        (
            "assumed_link_mass_kg = 0\n",
            ErrorKind::InvalidValue,
            "assumed_link_mass_kg",
        ),
        (
            "assumed_link_mass_kg = -2\n",
            ErrorKind::InvalidValue,
            "assumed_link_mass_kg",
        ),
        (
            "assumed_link_mass_kg = 1e5\n",
            ErrorKind::InvalidValue,
            "assumed_link_mass_kg",
        ),
        (
            "assumed_link_mass_kg = nan\n",
            ErrorKind::NonFinite,
            "assumed_link_mass_kg",
        ),
    ];
    for (tail, kind, needle) in cases {
        let e = parse(&format!("robot = \"r.urdf\"\n{tail}")).unwrap_err();
        assert_eq!(e.kind, kind, "{tail}: {e}");
        assert!(e.message.contains(needle), "{tail}: {e}");
        assert_eq!(e.file, Path::new("s.toml"));
    }
    let e = parse("base_link = \"b\"\n").unwrap_err();
    assert!(e.message.contains("robot"), "robot is required: {e}");
}

#[test]
fn job_resolves_the_robot_relative_to_the_setup() {
    let job = Job::load(fixtures().join("io_setup.toml")).unwrap();
    assert_eq!(job.setup.robot, Path::new("io_small.urdf"));
    assert_eq!(job.robot.file, fixtures().join("io_small.urdf"));
    assert_eq!(job.robot.joint_names, ["j1", "j2", "j3"]);
    assert_eq!(job.setup.model.geometry, GeometryModel::JointOffsets);

    // From another directory, one level down: `../`.
    let dir = std::env::temp_dir().join(format!("robcal-io-setup-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("robots")).unwrap();
    std::fs::copy(
        fixtures().join("io_small.urdf"),
        dir.join("robots/arm.urdf"),
    )
    .unwrap();
    std::fs::create_dir_all(dir.join("jobs")).unwrap();
    let setup = dir.join("jobs/s.toml");
    let write = |text: &str| std::fs::write(&setup, text).unwrap();

    write("robot = \"../robots/arm.urdf\"\ntip_link = \"l3\"\n");
    let job = Job::load(&setup).unwrap();
    assert_eq!(job.robot.base_link, "world");
    assert_eq!(job.robot.tip_link, "l3");

    // Model joints must be movable joints of the chain.
    write("robot = \"../robots/arm.urdf\"\ntip_link = \"l3\"\n[model]\ncompliance = [\"j1\", \"mount\"]\n");
    let e = Job::load(&setup).unwrap_err();
    assert_eq!(
        (e.kind, e.file.as_path()),
        (ErrorKind::UnknownKey, setup.as_path())
    );
    assert!(
        e.message
            .starts_with("model.compliance: 'mount' is not a movable joint"),
        "{e}"
    );
    write("robot = \"../robots/arm.urdf\"\ntip_link = \"l3\"\n[model]\ncompliance_by_angle = [\"j3\"]\n");
    let e = Job::load(&setup).unwrap_err();
    assert!(e.message.contains("'j3' is prismatic"), "{e}");

    // A robot that is not there: the error names the URDF path.
    write("robot = \"arm.urdf\"\n");
    let e = Job::load(&setup).unwrap_err();
    assert_eq!((e.kind, e.file), (ErrorKind::Io, dir.join("jobs/arm.urdf")));
    // A tip that is not a link: named.
    write("robot = \"../robots/arm.urdf\"\ntip_link = \"hand\"\n");
    let e = Job::load(&setup).unwrap_err();
    assert!(e.message.contains("tip_link 'hand'"), "{e}");

    let e = Job::load(dir.join("jobs/missing.toml")).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Io);
    std::fs::remove_dir_all(&dir).unwrap();
}
