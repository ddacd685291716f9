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
            for (name, f, a) in [
                ("reg", &t.registration, &t.registration_active),
                ("off", &t.offsets, &t.offsets_active),
                ("full", &t.full, &t.full_active),
            ] {
                println!("{points:?} {name} n={} it={} train {:.3} valid {:.3}  all-train {:.3} all-valid {:.3}", count(a), f.iterations, f.model.rmse_mm(&cols, &train, BL), f.model.rmse_mm(&cols, &valid, BL), f.model.rmse_all_mm(&cols, &train), f.model.rmse_all_mm(&cols, &valid));
            }
            println!(
                "markers {:?}",
                t.registration
                    .model
                    .markers
                    .iter()
                    .map(|m| (m * 1e3).as_slice().to_vec())
                    .collect::<Vec<_>>()
            );
            let names: Vec<String> = (0..cols.len())
                .filter(|&i| t.full_active[i])
                .map(|i| format!("{}={:.2}", cols.name(i), 0.0))
                .collect();
            println!("full params: {names:?}");
        }
    });
}
