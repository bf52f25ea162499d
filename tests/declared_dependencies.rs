//! The dependencies our FMUs declare are the real ones: in initialization mode each input
//! is perturbed alone and every output that moves must list that input among its
//! `InitialUnknowns` dependencies (and, for the step, among its `Outputs` dependencies when
//! it moves without a step). Hosts such as OMSimulator build their initialisation loops
//! from these lists.

mod common;

use tb_fmi::{Causality, FmuInstance, Instance, ScalarType};

fn perturbed(v: &tb_fmi::import::description::ScalarVariable) -> f64 {
    let x = v.start_f64().unwrap_or(0.0);
    let dx = 0.25 * x.abs().max(1.0);
    let up = x + dx;
    match v.max {
        Some(m) if up > m => x - dx,
        _ => up,
    }
}

/// Checks one model's declarations; returns how many inputs it perturbed.
fn check(model: &str) -> usize {
    let fmu = common::load(model);
    let md = &fmu.description;
    let mut inst = common::instantiate(&fmu, "dep", false);
    inst.set_echo(false);
    inst.setup_experiment(0.0.into()).unwrap();
    inst.enter_initialization_mode().unwrap();
    let index = |vr: u32| {
        md.variables
            .iter()
            .position(|v| v.value_reference == vr && v.ty == ScalarType::Real)
            .unwrap()
            + 1
    };
    let outputs: Vec<&tb_fmi::import::description::ScalarVariable> = md
        .variables
        .iter()
        .filter(|v| v.causality == Causality::Output && v.ty == ScalarType::Real)
        .collect();
    let out_vrs: Vec<u32> = outputs.iter().map(|v| v.value_reference).collect();
    let read = |inst: &mut Instance| {
        let mut y = vec![0.0; out_vrs.len()];
        inst.get_real(&out_vrs, &mut y).unwrap();
        y
    };
    let inputs: Vec<&tb_fmi::import::description::ScalarVariable> = md
        .variables
        .iter()
        .filter(|v| v.causality == Causality::Input && v.ty == ScalarType::Real)
        .collect();
    // Phase 1, initialization mode: the InitialUnknowns' lists; phase 2, after it, without
    // a step: the Outputs' lists.
    let mut wrong = Vec::new();
    let mut moved_any = 0;
    for phase in [1, 2] {
        if phase == 2 {
            inst.exit_initialization_mode().unwrap();
        }
        let base = read(&mut inst);
        for u in &inputs {
            let x0 = u.start_f64().unwrap_or(0.0);
            inst.set_real(&[u.value_reference], &[perturbed(u)])
                .unwrap();
            let y = read(&mut inst);
            for (k, o) in outputs.iter().enumerate() {
                if y[k].to_bits() == base[k].to_bits() {
                    continue;
                }
                moved_any += 1;
                let i = index(o.value_reference);
                let list = if phase == 1 {
                    &md.initial_unknowns
                } else {
                    &md.outputs
                };
                let declared = list
                    .iter()
                    .find(|x| x.index == i)
                    .and_then(|x| x.dependencies.clone());
                if !declared
                    .as_ref()
                    .is_some_and(|d| d.contains(&index(u.value_reference)))
                {
                    wrong.push(format!(
                        "output '{}' moves with input '{}' {}, but {} declares {declared:?}",
                        o.name,
                        u.name,
                        if phase == 1 {
                            "in initialization mode"
                        } else {
                            "without a step"
                        },
                        if phase == 1 {
                            "its InitialUnknown"
                        } else {
                            "<Outputs>"
                        },
                    ));
                }
            }
            inst.set_real(&[u.value_reference], &[x0]).unwrap();
            assert_eq!(read(&mut inst), base, "{model}: restoring '{}'", u.name);
        }
    }
    assert!(wrong.is_empty(), "{model}:\n  {}", wrong.join("\n  "));
    eprintln!(
        "{model}: {} inputs perturbed, {moved_any} output moves, all declared",
        inputs.len()
    );
    // Every InitialUnknown declares its dependencies (no attribute = "every input").
    for u in &md.initial_unknowns {
        assert!(
            u.dependencies.is_some(),
            "{model}: InitialUnknown {} declares no dependencies",
            md.variables[u.index - 1].name
        );
    }
    inputs.len()
}

/// Every model of the registry, the test FMUs too.
#[test]
fn every_model_declares_what_its_outputs_depend_on() {
    let models = twinbench::pack::models();
    assert!(models.len() >= 5, "the registry lists the models");
    let perturbed: usize = models.iter().map(|s| check(s.info.name)).sum();
    assert!(perturbed > 0, "no input perturbed in any model");
}
