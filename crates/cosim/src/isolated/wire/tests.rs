//! The protocol's round trips, truncations and codes.

use super::*;

#[test]
fn decoder_refuses_truncated_and_oversized_counts() {
    let mut d = Dec::new(&[5, 0, 0, 0, 1, 2]);
    assert_eq!(d.count(4).unwrap_err(), WireError::Count { count: 5 });
    let mut d = Dec::new(&[1, 0]);
    assert!(matches!(d.u32().unwrap_err(), WireError::Truncated { .. }));
}

fn target() -> LibraryTarget {
    LibraryTarget {
        path: "/c/x.so".into(),
        source: "x.fmu".into(),
        model_identifier: "x".into(),
        preload: vec!["libpython3.11.so".into(), "b".into()],
        description: "/c/modelDescription.xml".into(),
        model_exchange: true,
        tolerance: 1e-6,
        checks: vec![FileCheck {
            base: "/c".into(),
            rel: "0123/x.so".into(),
            size: 1 << 31,
            mode: 0o700,
            hash: "ab".repeat(32),
        }],
    }
}

#[test]
fn library_targets_round_trip_and_truncation_is_refused() {
    let t = target();
    let mut e = Enc::default();
    t.encode(&mut e);
    assert_eq!(LibraryTarget::decode(&mut Dec::new(&e.0)).unwrap(), t);
    let cut = &e.0[..e.0.len() - 3];
    assert!(LibraryTarget::decode(&mut Dec::new(cut)).is_err());
}

#[test]
fn fmi_calls_are_coded_by_the_function_table() {
    assert_eq!(function_of(op::DO_STEP), Some(Function::DoStep));
    assert_eq!(function_of(op::GET_REAL).unwrap().name(), "fmi2GetReal");
    assert_eq!(function_of(op::INSTANTIATE), Some(Function::Instantiate));
    assert_eq!(function_of(150), None);
    // The protocol's own codes are outside the table.
    assert!(Function::from_u8(op::INSTANTIATE).is_none());
    assert!(Function::from_u8(op::PROBE).is_none());
    assert!(Function::from_u8(op::QUIT).is_none());
}

/// The variant's number (no wildcard: a new variant does not compile until it is
/// numbered here and given an example in [`every_request`]).
fn variant(r: &Request) -> usize {
    match r {
        Request::Instantiate { .. } => 0,
        Request::Probe(_) => 1,
        Request::Quit => 2,
        Request::SetDebugLogging(_) => 3,
        Request::SetupExperiment { .. } => 4,
        Request::EnterInit => 5,
        Request::ExitInit => 6,
        Request::Terminate => 7,
        Request::Reset => 8,
        Request::SetReal { .. } => 9,
        Request::SetInteger { .. } => 10,
        Request::SetBoolean { .. } => 11,
        Request::SetString { .. } => 12,
        Request::GetReal { .. } => 13,
        Request::GetInteger { .. } => 14,
        Request::GetBoolean { .. } => 15,
        Request::GetString { .. } => 16,
        Request::FmuTerminated => 17,
        Request::DoStep { .. } => 18,
        Request::Realtime(_) => 19,
    }
}
const VARIANTS: usize = 20;

/// At least one request of every variant.
fn every_request() -> Vec<Request<'static>> {
    vec![
        Request::Instantiate {
            library: target(),
            name: "dyno_rl".into(),
            guid: "{1-2}".into(),
            resources: "/c/resources".into(),
            logging: true,
        },
        Request::Probe(target()),
        Request::Quit,
        Request::SetDebugLogging(true),
        Request::SetDebugLogging(false),
        Request::SetupExperiment {
            start: 0.5,
            stop: Some(98.5),
            tolerance: Some(1e-6),
        },
        Request::SetupExperiment {
            start: -1.0,
            stop: None,
            tolerance: None,
        },
        Request::EnterInit,
        Request::ExitInit,
        Request::Terminate,
        Request::Reset,
        Request::SetReal {
            vrs: vec![1, 7].into(),
            values: vec![1.5, -0.0].into(),
        },
        Request::SetInteger {
            vrs: vec![3].into(),
            values: vec![i32::MIN].into(),
        },
        Request::SetBoolean {
            vrs: vec![4, 5].into(),
            values: vec![1, 0].into(),
        },
        Request::SetString {
            vrs: vec![8, 9].into(),
            values: vec!["lap \u{e9}".into(), "".into()],
        },
        Request::GetReal {
            vrs: vec![100, 101, 102].into(),
        },
        Request::GetInteger { vrs: vec![].into() },
        Request::GetBoolean {
            vrs: vec![6].into(),
        },
        Request::GetString {
            vrs: vec![9, 9].into(),
        },
        Request::FmuTerminated,
        Request::DoStep { t: 1.25, h: 1e-3 },
        Request::Realtime("{\"steps\": 3}".into()),
    ]
}

#[test]
fn every_request_round_trips_alone_and_in_sequence() {
    let all = every_request();
    let mut seen: Vec<usize> = all.iter().map(variant).collect();
    seen.dedup();
    assert_eq!(
        seen,
        (0..VARIANTS).collect::<Vec<_>>(),
        "every variant, in order"
    );
    // Each has a code of its own.
    let mut codes: Vec<u8> = all.iter().map(Request::code).collect();
    codes.sort();
    codes.dedup();
    assert_eq!(codes.len(), VARIANTS);
    let mut whole = Enc::default();
    for r in &all {
        let mut e = Enc::default();
        r.encode(&mut e);
        assert_eq!(e.0[0], r.code());
        let mut d = Dec::new(&e.0);
        assert_eq!(&Request::decode(&mut d).unwrap(), r);
        assert!(d.at_end(), "{r:?}");
        // Every proper prefix is refused, never misread.
        for cut in 0..e.0.len() {
            let mut d = Dec::new(&e.0[..cut]);
            assert!(Request::decode(&mut d).is_err(), "{r:?} cut at {cut}");
        }
        r.encode(&mut whole);
    }
    let mut d = Dec::new(&whole.0);
    for r in &all {
        assert_eq!(&Request::decode(&mut d).unwrap(), r);
    }
    assert!(d.at_end());
    // Borrowed arrays encode as owned ones do.
    let (vrs, values) = ([1u32, 2], [0.5, 0.25]);
    let (mut a, mut b) = (Enc::default(), Enc::default());
    Request::SetReal {
        vrs: Cow::Borrowed(&vrs),
        values: Cow::Borrowed(&values),
    }
    .encode(&mut a);
    Request::SetReal {
        vrs: vrs.to_vec().into(),
        values: values.to_vec().into(),
    }
    .encode(&mut b);
    assert_eq!(a.0, b.0);
}

#[test]
fn over_long_counts_and_unknown_codes_are_refused() {
    // A count of value references beyond the frame.
    let mut e = Enc::default();
    e.u8(op::GET_REAL);
    e.u32(u32::MAX);
    e.u32(1);
    let err = Request::decode(&mut Dec::new(&e.0)).unwrap_err();
    assert_eq!(
        err,
        WireError::Count {
            count: u32::MAX as usize
        }
    );
    assert_eq!(err.to_string(), "count 4294967295 exceeds the message");
    // A set with fewer values than value references.
    let mut e = Enc::default();
    e.u8(op::SET_REAL);
    e.vrs(&[1, 2]);
    e.f64(1.0);
    let err = Request::decode(&mut Dec::new(&e.0)).unwrap_err();
    assert!(matches!(err, WireError::Truncated { .. }), "{err}");
    // A string longer than the frame.
    let mut e = Enc::default();
    e.u8(op::SET_STRING);
    e.vrs(&[1]);
    e.u32(1000);
    let err = Request::decode(&mut Dec::new(&e.0)).unwrap_err();
    assert!(matches!(err, WireError::Truncated { .. }), "{err}");
    assert_eq!(
        Request::decode(&mut Dec::new(&[150])).unwrap_err(),
        WireError::UnknownOperation(150)
    );
}

/// A request with one get of each answer, and responses to it.
fn gets() -> Vec<Request<'static>> {
    vec![
        Request::SetReal {
            vrs: vec![1].into(),
            values: vec![2.0].into(),
        },
        Request::DoStep { t: 0.0, h: 0.5 },
        Request::GetReal {
            vrs: vec![1, 2].into(),
        },
        Request::GetInteger {
            vrs: vec![3].into(),
        },
        Request::GetBoolean {
            vrs: vec![4, 4].into(),
        },
        Request::GetString {
            vrs: vec![5, 6].into(),
        },
        Request::FmuTerminated,
    ]
}

fn every_response() -> Vec<Response> {
    let complete = vec![
        Values::Real(vec![0.5, -2.0]),
        Values::Int(vec![7]),
        Values::Int(vec![1, 0]),
        Values::Text(vec!["a".into(), "".into()]),
        Values::Real(vec![1.0, 0.25]),
    ];
    let failures = [
        Failure::Call {
            function: FmiFunction::Fmi2(Function::DoStep),
            status: CallStatus::Fmi2(fmi2Status::ERROR),
            time: 0.5,
            log: vec!["[Error] it failed".into(), "".into()],
        },
        Failure::Call {
            function: FmiFunction::Fmi2(Function::GetReal),
            status: CallStatus::Fmi2(fmi2Status(77)),
            time: 0.0,
            log: vec![],
        },
        Failure::Call {
            function: FmiFunction::Fmi3("fmi3DoStep".into()),
            status: CallStatus::Fmi3(3),
            time: 0.25,
            log: vec!["[Error] a step of an FMI 3.0 FMU".into()],
        },
        Failure::EarlyReturn {
            time: 0.25,
            last: 0.3,
            target: 0.5,
            log: vec!["[Warning] returned early".into()],
        },
        Failure::ModelExchange {
            fmu: "m.fmu".into(),
            call: "CVode".into(),
            problem: "returned CV_CONV_FAILURE (-4): failed".into(),
            time: 0.125,
            log: vec!["[Error] no".into()],
        },
        Failure::Instantiate("GUID {a} differs".into()),
        Failure::Unsupported(Some(Function::GetBooleanStatus)),
        Failure::Unsupported(None),
        Failure::Other("no instance: instantiate first".into()),
    ];
    let mut all = vec![
        Response {
            time: 0.5,
            results: complete.clone(),
            error: None,
        },
        Response {
            time: 0.0,
            results: vec![],
            error: None,
        },
    ];
    for (k, f) in failures.into_iter().enumerate() {
        all.push(Response {
            time: k as f64,
            results: complete[..k.min(complete.len())].to_vec(),
            error: Some(f),
        });
    }
    all
}

#[test]
fn every_response_round_trips_and_a_cut_one_is_refused() {
    let ops = gets();
    for r in every_response() {
        let mut e = Enc::default();
        r.encode(&mut e);
        assert_eq!(Response::decode(&e.0, &ops).unwrap(), r);
        for cut in 0..e.0.len() {
            assert!(
                Response::decode(&e.0[..cut], &ops).is_err(),
                "{r:?} cut at {cut}"
            );
        }
        let mut longer = e.0.clone();
        longer.push(0);
        assert_eq!(
            Response::decode(&longer, &ops).unwrap_err(),
            WireError::Trailing
        );
    }
}

#[test]
fn forged_responses_are_refused() {
    let ops = gets();
    let head = |ok: u8, n: u32| {
        let mut e = Enc::default();
        e.u8(ok);
        e.u32(n);
        e.f64(0.0);
        e
    };
    // More results than gets.
    let e = head(0, 6);
    assert_eq!(
        Response::decode(&e.0, &ops).unwrap_err(),
        WireError::Results {
            results: 6,
            gets: 5
        }
    );
    // A function code outside the table, a version that is not FMI's, an unknown error
    // kind: a failure whose bytes after the head are `tail`.
    let failure = |tail: &[u8]| {
        let mut e = head(1, 0);
        tail.iter().for_each(|&b| e.u8(b));
        Response::decode(&e.0, &ops).unwrap_err()
    };
    assert_eq!(
        failure(&[kind::CALL, 2, 250]),
        WireError::UnknownFunction(250)
    );
    assert_eq!(failure(&[kind::CALL, 7]), WireError::UnknownVersion(7));
    assert_eq!(failure(&[9]), WireError::UnknownKind(9));
    // A log count beyond the frame.
    let mut e = head(1, 0);
    e.u8(kind::CALL);
    e.u8(2);
    e.u8(Function::GetReal as u8);
    e.u8(2);
    e.i32(3);
    e.f64(0.0);
    e.u32(u32::MAX);
    let err = Response::decode(&e.0, &ops).unwrap_err();
    assert!(matches!(err, WireError::Count { .. }), "{err}");
}

#[test]
fn frames_carry_their_length() {
    let mut e = Enc::default();
    e.start_frame();
    Request::DoStep { t: 0.0, h: 1.0 }.encode(&mut e);
    let bytes = e.finish_frame().to_vec();
    assert_eq!(bytes.len(), 4 + 17);
    assert_eq!(u32::from_le_bytes(bytes[..4].try_into().unwrap()), 17);
    // Started again, the frame is empty (its buffer kept).
    e.start_frame();
    assert_eq!(e.finish_frame(), [0, 0, 0, 0]);
}
