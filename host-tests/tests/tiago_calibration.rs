//! TIAGo mocap calibration (issue 7): the FIGAROH table and the closed loop.

mod tiago_common;
use tiago_common::*;

#[test]
fn explore() {
    with_stack(|| {
        let job = job();
        let dir = temp_dir("explore");
        let train = postures(&import(&job, TRAIN, &dir), &job.robot);
        let valid = postures(&import(&job, VALID, &dir), &job.robot);
        let cols = Columns::new(&job.robot.chain);
        let markers = job
            .setup
            .markers
            .iter()
            .map(|m| nalgebra::Vector3::from(m.xyz))
            .collect::<Vec<_>>();
        let markers = [markers[0], markers[1], markers[2], markers[3]];
        for points in [vec![BL], vec![0, 1, 2, 3]] {
            let t = table(&job.robot, markers, &cols, &train, &points);
            let id = identifiable_geometry(&t.registration.model, &cols, &train, &points);
            let lib = candidates(&cols, &id.kept);
            for (label, start, act, lib) in [
                (
                    "from registration",
                    &t.registration,
                    &t.registration_active,
                    lib.clone(),
                ),
                (
                    "from full",
                    &t.full,
                    &t.full_active,
                    lib.iter()
                        .filter(|c| {
                            !c.name.starts_with("joint_offset") && !c.name.starts_with("geometry")
                        })
                        .cloned()
                        .collect(),
                ),
            ] {
                let now = std::time::Instant::now();
                let l = closed_loop(start, act, &cols, &train, &valid, &points, &lib);
                println!("== {points:?} {label}: {:?}", now.elapsed());
                for s in &l.steps {
                    println!("  + {:32} p={:.2e} n={} train {:.3}->{:.3} cv {:.3}->{:.3} valid {:.3}->{:.3}", s.effect, s.p_value, s.params, s.train_before_mm, s.train_after_mm, s.cv_before_mm, s.cv_after_mm, s.valid_before_mm, s.valid_after_mm);
                }
                for r in &l.rejected {
                    println!("  rejected {:?}", r);
                }
                for i in 0..cols.len() {
                    if l.active[i] && i >= 18 {
                        print!(
                            "{}={:.3}{} ",
                            cols.name(i),
                            l.fitted.model.effect[i],
                            cols.unit(i)
                        );
                    }
                }
                println!();
            }
        }
    });
}
