//! Encoding and decoding with validation at the boundary (PROTOCOL.md, "Encoding").
//!
//! `decode` never panics: it checks the protocol version first (so a peer of another version
//! gets an error naming both versions, not a confusing field error), then the full message,
//! then the run id.

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::messages::{Command, InterfaceForces, InterfaceKinematics, InterfaceMesh, Status};
use crate::{ProtoError, PROTOCOL_VERSION};

/// A message type of the protocol.
pub trait Message: Serialize + DeserializeOwned {
    /// Name used in errors.
    const WHAT: &'static str;
    fn version(&self) -> u32;
    fn run_id(&self) -> &str;
    /// Bytes of the bulk arrays, so that encoding allocates its buffer once.
    fn bulk_bytes(&self) -> usize {
        0
    }
    /// Number of bulk arrays (each one MessagePack `bin`).
    fn bulk_arrays(&self) -> usize {
        0
    }
}

macro_rules! message {
    ($t:ty, $what:literal $(, $array:ident)*) => {
        impl Message for $t {
            const WHAT: &'static str = $what;
            fn version(&self) -> u32 {
                self.version
            }
            fn run_id(&self) -> &str {
                &self.run_id
            }
            fn bulk_bytes(&self) -> usize {
                0 $(+ 8 * self.$array.len())*
            }
            fn bulk_arrays(&self) -> usize {
                0 $(+ { let _ = &self.$array; 1 })*
            }
        }
    };
}
message!(Command, "command");
message!(Status, "status");
message!(InterfaceMesh, "interface mesh", positions);
message!(
    InterfaceKinematics,
    "interface kinematics",
    positions,
    velocities,
    accelerations
);
message!(InterfaceForces, "interface forces", forces);

/// Encodes a message as a MessagePack map with named fields.
pub fn encode<M: Message>(msg: &M) -> Result<Vec<u8>, ProtoError> {
    let mut buf = Vec::with_capacity(msg.bulk_bytes() + 256);
    rmp_serde::encode::write_named(&mut buf, msg).map_err(|e| ProtoError::Encode {
        what: M::WHAT,
        reason: e.to_string(),
    })?;
    Ok(buf)
}

/// Bytes [`encode`] would produce, without producing them (the bulk arrays are counted, not
/// copied), so that a message can be written straight into a buffer of the right size.
pub fn encoded_len<M: Message>(msg: &M) -> Result<usize, ProtoError> {
    struct Count(usize);
    impl std::io::Write for Count {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0 += b.len();
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    let mut count = Count(0);
    rmp_serde::encode::write_named(&mut count, msg).map_err(|e| ProtoError::Encode {
        what: M::WHAT,
        reason: e.to_string(),
    })?;
    Ok(count.0)
}

/// Encodes `msg` into `buf`, which must be exactly [`encoded_len`] bytes long, checking the
/// bulk arrays for NaN and infinity on the way (the copy and the check in one pass). Returns
/// `true` when every bulk byte was checked and finite; `false` means "not known": the caller
/// checks the message itself before sending it.
pub fn encode_into_checked<M: Message>(msg: &M, buf: &mut [u8]) -> Result<bool, ProtoError> {
    /// Writes of whole doubles of at least 64 bytes are taken for the bulk arrays (MessagePack
    /// writes a `bin` payload in one call): copied with the check. The verdict holds only if
    /// exactly as many writes as the message has arrays, of exactly its bulk bytes, were
    /// checked: a skipped short array (< 64 bytes) and a long string taken for one cannot
    /// balance both counts (the string is longer than the array), so any such mix-up gives
    /// "not known".
    struct Checking<'a> {
        rest: &'a mut [u8],
        checked: usize,
        writes: usize,
        finite: bool,
    }
    impl std::io::Write for Checking<'_> {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            if b.len() > self.rest.len() {
                return Err(std::io::ErrorKind::WriteZero.into());
            }
            let (head, tail) = std::mem::take(&mut self.rest).split_at_mut(b.len());
            if b.len() >= 64 && b.len() % 8 == 0 {
                self.finite &= crate::messages::copy_finite(head, b);
                self.checked += b.len();
                self.writes += 1;
            } else {
                head.copy_from_slice(b);
            }
            self.rest = tail;
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }
    let len = buf.len();
    let mut w = Checking {
        rest: buf,
        checked: 0,
        writes: 0,
        finite: true,
    };
    rmp_serde::encode::write_named(&mut w, msg).map_err(|e| ProtoError::Encode {
        what: M::WHAT,
        reason: format!("into a buffer of {len} bytes: {e}"),
    })?;
    if !w.rest.is_empty() {
        return Err(ProtoError::Encode {
            what: M::WHAT,
            reason: format!("{} of {len} bytes left unwritten", w.rest.len()),
        });
    }
    Ok(w.finite && w.checked == msg.bulk_bytes() && w.writes == msg.bulk_arrays())
}

#[derive(Deserialize)]
struct VersionProbe {
    version: u32,
}

/// [`decode`], checking the bulk arrays for NaN and infinity while they are copied (one pass).
/// Returns the message and whether all its arrays are known to be finite; `false` means a
/// non-finite value is in there, and the message's `validate` names it.
pub fn decode_finite<M: Message>(
    bytes: &[u8],
    expected_run: &str,
) -> Result<(M, bool), ProtoError> {
    match crate::messages::finite_only(|| decode::<M>(bytes, expected_run)) {
        Err(ProtoError::Decode { reason, .. }) if reason.contains(crate::messages::NON_FINITE) => {
            Ok((decode::<M>(bytes, expected_run)?, false))
        }
        other => other.map(|m| (m, true)),
    }
}

/// Decodes and checks a message: version, structure, run id. Never panics.
pub fn decode<M: Message>(bytes: &[u8], expected_run: &str) -> Result<M, ProtoError> {
    let probe: VersionProbe = rmp_serde::from_slice(bytes).map_err(|e| ProtoError::Decode {
        what: M::WHAT,
        reason: format!("not a MessagePack map with a `version` field: {e}"),
    })?;
    if probe.version != PROTOCOL_VERSION {
        return Err(ProtoError::Version {
            what: M::WHAT,
            got: probe.version,
            expected: PROTOCOL_VERSION,
        });
    }
    let msg: M = rmp_serde::from_slice(bytes).map_err(|e| ProtoError::Decode {
        what: M::WHAT,
        reason: e.to_string(),
    })?;
    if msg.run_id() != expected_run {
        return Err(ProtoError::WrongRun {
            what: M::WHAT,
            got: msg.run_id().to_string(),
            expected: expected_run.to_string(),
        });
    }
    Ok(msg)
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use proptest::prelude::*;

    use super::*;
    use crate::messages::*;

    const RUN: &str = "r1";

    fn all_messages() -> (
        Vec<Command>,
        Vec<Status>,
        InterfaceMesh,
        InterfaceKinematics,
        InterfaceForces,
    ) {
        let commands = vec![
            CommandBody::Init(Init {
                scene_path: "scenes/beam.toml".into(),
                scene_toml: "[scene]\nname = \"beam\"\n".into(),
                out_dir: "out/beam".into(),
                table: "fem".into(),
                interfaces: vec![InterfaceDecl {
                    name: "top".into(),
                    kind: InterfaceKind::Surface,
                    provider: "fem".into(),
                    users: vec!["dem".into()],
                    force_averaging: true,
                    relaxed_forces: false,
                    relaxed_kinematics: false,
                }],
                check_only: false,
                trace: true,
            }),
            CommandBody::Publish {
                label: Label::window(0),
            },
            CommandBody::AdvanceWindow(AdvanceWindow {
                window: 3,
                iteration: 1,
                t_start: 3e-4,
                dt: 1e-4,
                motion: MotionRule::Linear,
                input: Some(Label::window(2)),
                output: Some(Label {
                    window: 3,
                    iteration: 1,
                }),
                static_solve: false,
            }),
            CommandBody::Checkpoint { window: 3 },
            CommandBody::Rollback { window: 3 },
            CommandBody::Snapshot {
                window: 7,
                path: "ck/7".into(),
            },
            CommandBody::Restore {
                window: 7,
                path: "ck/7".into(),
            },
            CommandBody::Stop {
                reason: "end time reached".into(),
            },
        ]
        .into_iter()
        .enumerate()
        .map(|(i, b)| Command::new(RUN, i as u64, b))
        .collect();
        let limits = BTreeMap::from([("time_step".to_string(), 1e-6)]);
        let statuses = vec![
            StatusBody::Hello(Hello {
                software: "dem-node 0.1".into(),
                kind: NodeKind::Dem,
                capabilities: vec!["snapshot".into()],
                pid: 42,
            }),
            StatusBody::Ready {
                limits: limits.clone(),
                warnings: vec!["w".into()],
            },
            StatusBody::WindowDone {
                window: 3,
                t_end: 4e-4,
                compute_s: 0.1,
                wait_s: 0.01,
                monitor: limits.clone(),
                after_output_s: 0.02,
            },
            StatusBody::SnapshotDone {
                window: 7,
                path: "ck/7".into(),
            },
            StatusBody::Restored { window: 7 },
            StatusBody::Stopped {
                results: limits,
                compute_s: 1.0,
                wait_s: 0.5,
            },
            StatusBody::Error {
                code: ErrorCode::Unstable,
                message: "NaN".into(),
                window: Some(9),
            },
        ]
        .into_iter()
        .map(|b| Status::new(RUN, "dem", b))
        .collect();
        let mesh = InterfaceMesh {
            version: PROTOCOL_VERSION,
            run_id: RUN.into(),
            interface: "top".into(),
            node_ids: vec![1, 2, 3],
            positions: vec![0., 0., 0., 1., 0., 0., 0., 1., 0.].into(),
            triangles: vec![0, 1, 2],
            volume: None,
        };
        let kin = InterfaceKinematics {
            version: PROTOCOL_VERSION,
            run_id: RUN.into(),
            interface: "top".into(),
            window: 5,
            iteration: 0,
            time: 0.5,
            positions: vec![0.5; 9].into(),
            velocities: vec![-1.0; 9].into(),
            accelerations: vec![2.0; 9].into(),
        };
        let forces = InterfaceForces {
            version: PROTOCOL_VERSION,
            run_id: RUN.into(),
            interface: "top".into(),
            window: 5,
            iteration: 0,
            time: 0.5,
            forces: vec![1e3; 9].into(),
            averaged: true,
            samples: 10,
        };
        (commands, statuses, mesh, kin, forces)
    }

    fn round_trip<M: Message + PartialEq + std::fmt::Debug>(m: &M) {
        let bytes = encode(m).unwrap();
        let back: M = decode(&bytes, RUN).unwrap();
        assert_eq!(&back, m);
    }

    #[test]
    fn every_message_type_round_trips() {
        let (commands, statuses, mesh, kin, forces) = all_messages();
        commands.iter().for_each(round_trip);
        statuses.iter().for_each(round_trip);
        round_trip(&mesh);
        round_trip(&kin);
        round_trip(&forces);
        mesh.validate().unwrap();
        kin.validate(3, Label::window(5)).unwrap();
        forces.validate(3, Label::window(5)).unwrap();
    }

    #[test]
    fn a_window_done_without_after_output_s_reads_as_zero() {
        // what a node written before the field (or one that does not measure it) sends
        #[derive(serde::Serialize)]
        #[serde(tag = "type", rename_all = "snake_case")]
        enum OldBody {
            WindowDone {
                window: u64,
                t_end: f64,
                compute_s: f64,
                wait_s: f64,
                monitor: BTreeMap<String, f64>,
            },
        }
        #[derive(serde::Serialize)]
        struct OldStatus {
            version: u32,
            run_id: String,
            node: String,
            body: OldBody,
        }
        let old = OldStatus {
            version: PROTOCOL_VERSION,
            run_id: RUN.into(),
            node: "fem".into(),
            body: OldBody::WindowDone {
                window: 3,
                t_end: 4e-4,
                compute_s: 0.1,
                wait_s: 0.01,
                monitor: BTreeMap::new(),
            },
        };
        let bytes = rmp_serde::to_vec_named(&old).unwrap();
        let s: Status = decode(&bytes, RUN).unwrap();
        assert!(
            matches!(s.body, StatusBody::WindowDone { window: 3, compute_s, after_output_s, .. } if compute_s == 0.1 && after_output_s == 0.0),
            "{s:?}"
        );
    }

    #[test]
    fn another_protocol_version_is_refused_naming_both() {
        let (_, _, _, mut kin, _) = all_messages();
        kin.version = PROTOCOL_VERSION + 1;
        let bytes = encode(&kin).unwrap();
        let err = decode::<InterfaceKinematics>(&bytes, RUN).unwrap_err();
        let text = err.to_string();
        assert!(
            matches!(err, ProtoError::Version { got, expected, .. } if got == PROTOCOL_VERSION + 1 && expected == PROTOCOL_VERSION)
        );
        assert!(
            text.contains(&format!("version {}", PROTOCOL_VERSION + 1)),
            "{text}"
        );
        assert!(
            text.contains(&format!("version {PROTOCOL_VERSION}")),
            "{text}"
        );
    }

    #[test]
    fn another_run_is_refused() {
        let (_, _, _, _, forces) = all_messages();
        let bytes = encode(&forces).unwrap();
        let err = decode::<InterfaceForces>(&bytes, "other").unwrap_err();
        assert!(matches!(err, ProtoError::WrongRun { .. }), "{err}");
    }

    #[test]
    fn validation_names_window_size_and_nan() {
        let (_, _, mut mesh, mut kin, mut forces) = all_messages();
        assert!(matches!(
            kin.validate(3, Label::window(6)),
            Err(ProtoError::WrongWindow {
                got: Label {
                    window: 5,
                    iteration: 0
                },
                expected: Label {
                    window: 6,
                    iteration: 0
                },
                ..
            })
        ));
        assert!(matches!(
            kin.validate(4, Label::window(5)),
            Err(ProtoError::Size {
                field: "positions",
                got: 9,
                expected: 12,
                ..
            })
        ));
        kin.accelerations.0[4] = f64::NAN;
        let e = kin.validate(3, Label::window(5)).unwrap_err();
        assert!(
            matches!(
                e,
                ProtoError::NotFinite {
                    field: "accelerations",
                    index: 4,
                    ..
                }
            ),
            "{e}"
        );
        forces.forces.0[8] = f64::INFINITY;
        assert!(matches!(
            forces.validate(3, Label::window(5)),
            Err(ProtoError::NotFinite {
                field: "forces",
                index: 8,
                ..
            })
        ));
        mesh.triangles = vec![0, 1, 3];
        assert!(mesh
            .validate()
            .unwrap_err()
            .to_string()
            .contains("node index 3"));
        mesh.triangles = vec![0, 1];
        assert!(mesh.validate().is_err());
    }

    /// A volume interface's mesh carries elements and weights (and no triangles); it round
    /// trips, an older message without the field reads as a surface, and bad elements or
    /// weights are refused naming them.
    #[test]
    fn volume_interface_meshes_round_trip_and_are_checked() {
        let (_, _, mut mesh, _, _) = all_messages();
        let surface = encode(&mesh).unwrap();
        assert_eq!(decode::<InterfaceMesh>(&surface, RUN).unwrap().volume, None);
        mesh.node_ids = vec![1, 2, 3, 4];
        mesh.positions = vec![0., 0., 0., 1., 0., 0., 0., 1., 0., 0., 0., 1.].into();
        mesh.triangles.clear();
        mesh.volume = Some(VolumeElements {
            shape: "tet4".into(),
            elements: vec![0, 1, 2, 3],
            weights: vec![0.0, 0.0, 0.5, 1.0].into(),
            penalty: 1e14,
        });
        round_trip(&mesh);
        mesh.validate().unwrap();
        let check = |m: &InterfaceMesh, needle: &str| {
            let e = m.validate().unwrap_err().to_string();
            assert!(e.contains(needle), "{e}");
        };
        let mut bad = mesh.clone();
        bad.volume.as_mut().unwrap().weights.0[2] = 1.5;
        check(&bad, "weights[2] = 1.5");
        let mut bad = mesh.clone();
        bad.volume.as_mut().unwrap().elements[3] = 4;
        check(&bad, "node index 4");
        let mut bad = mesh.clone();
        bad.volume.as_mut().unwrap().shape = "wedge6".into();
        check(&bad, "unknown element shape `wedge6`");
        let mut bad = mesh.clone();
        bad.triangles = vec![0, 1, 2];
        check(&bad, "not triangles");
        let mut bad = mesh.clone();
        bad.volume.as_mut().unwrap().penalty = 0.0;
        check(&bad, "penalty 0");
        let mut bad = mesh.clone();
        bad.volume.as_mut().unwrap().elements = vec![0, 1, 2, 2];
        check(&bad, "element 0 repeats node index 2");
        let mut bad = mesh.clone();
        bad.node_ids.push(5);
        bad.positions.0.extend([2.0, 2.0, 2.0]);
        bad.volume.as_mut().unwrap().weights.0.push(0.0);
        check(&bad, "node 5 (index 4) is in no element");
    }

    #[test]
    fn f64_arrays_are_little_endian_bins_and_also_accepted_as_arrays() {
        let (_, _, _, kin, _) = all_messages();
        let bytes = encode(&kin).unwrap();
        // `positions` is a bin 8 (0xc4) of 72 bytes: 9 doubles.
        let needle = [0xc4u8, 72];
        let at = bytes.windows(2).position(|w| w == needle).unwrap() + 2;
        // … whose content is the doubles' little-endian bytes, value after value
        let want: Vec<u8> = kin
            .positions
            .as_slice()
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        assert_eq!(&bytes[at..at + 72], &want[..]);
        // decoding reads them back from wherever the bin lies (no alignment needed)
        let mut shifted = vec![0u8];
        shifted.extend_from_slice(&bytes);
        assert_eq!(
            decode::<InterfaceKinematics>(&shifted[1..], RUN).unwrap(),
            kin
        );
        // A hand-written message with plain float arrays decodes too.
        #[derive(Serialize)]
        struct Plain {
            version: u32,
            run_id: &'static str,
            interface: &'static str,
            window: u64,
            iteration: u32,
            time: f64,
            positions: Vec<f64>,
            velocities: Vec<f64>,
            accelerations: Vec<f64>,
        }
        let plain = Plain {
            version: PROTOCOL_VERSION,
            run_id: RUN,
            interface: "top",
            window: 5,
            iteration: 0,
            time: 0.5,
            positions: vec![0.5; 9],
            velocities: vec![-1.0; 9],
            accelerations: vec![2.0; 9],
        };
        let back: InterfaceKinematics =
            decode(&rmp_serde::to_vec_named(&plain).unwrap(), RUN).unwrap();
        assert_eq!(back, kin);
        // ... and the one-pass check sees its values too: a NaN in a plain array is not
        // vouched for, and `validate` names it
        let (back, finite) =
            decode_finite::<InterfaceKinematics>(&rmp_serde::to_vec_named(&plain).unwrap(), RUN)
                .unwrap();
        assert!(finite);
        assert_eq!(back, kin);
        let mut bad = plain;
        bad.velocities[4] = f64::NAN;
        let (back, finite) =
            decode_finite::<InterfaceKinematics>(&rmp_serde::to_vec_named(&bad).unwrap(), RUN)
                .unwrap();
        assert!(!finite);
        assert!(matches!(
            back.validate(3, Label::window(5)),
            Err(ProtoError::NotFinite {
                field: "velocities",
                index: 4,
                ..
            })
        ));
    }

    #[test]
    fn a_bin_that_is_not_whole_doubles_is_an_error() {
        let (_, _, _, kin, _) = all_messages();
        let mut bytes = encode(&kin).unwrap();
        let pos = bytes.windows(2).position(|w| w == [0xc4, 72]).unwrap();
        bytes[pos + 1] = 71; // claims 71 bytes: the rest of the message shifts
        assert!(decode::<InterfaceKinematics>(&bytes, RUN).is_err());
    }

    #[test]
    fn protocol_md_byte_example_is_what_the_codec_writes() {
        let doc = include_str!("../PROTOCOL.md");
        let section = &doc[doc.find("### Byte-level example").expect("section")..];
        let block = section.split("```").nth(1).expect("code block");
        let mut expected = Vec::new();
        for line in block.lines() {
            for tok in line.split_whitespace() {
                match (tok.len(), u8::from_str_radix(tok, 16)) {
                    (2, Ok(b)) => expected.push(b),
                    _ => break,
                }
            }
        }
        let msg = Status::new(
            "r1",
            "dem",
            StatusBody::Ready {
                limits: BTreeMap::from([("time_step".to_string(), 1e-6)]),
                warnings: vec![],
            },
        );
        assert_eq!(encode(&msg).unwrap(), expected);
    }

    fn decode_all(bytes: &[u8]) {
        let _ = decode::<Command>(bytes, RUN);
        let _ = decode::<Status>(bytes, RUN);
        let _ = decode::<InterfaceMesh>(bytes, RUN);
        let _ = decode::<InterfaceKinematics>(bytes, RUN);
        let _ = decode::<InterfaceForces>(bytes, RUN);
    }

    proptest! {
        // the fuzz campaign of the decoders: 10^5 random inputs, zero panics
        #![proptest_config(ProptestConfig::with_cases(100_000))]

        #[test]
        fn every_decoder_survives_100k_random_inputs(bytes in proptest::collection::vec(any::<u8>(), 0..256)) {
            decode_all(&bytes);
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(4000))]

        #[test]
        fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            decode_all(&bytes);
        }

        #[test]
        fn truncated_and_mutated_messages_give_errors_not_panics(
            which in 0usize..16, cut in 0.0f64..1.0, flip in any::<(usize, u8)>()
        ) {
            let (commands, statuses, mesh, kin, forces) = all_messages();
            let mut all: Vec<Vec<u8>> = commands.iter().map(|m| encode(m).unwrap()).collect();
            all.extend(statuses.iter().map(|m| encode(m).unwrap()));
            all.push(encode(&mesh).unwrap());
            all.push(encode(&kin).unwrap());
            all.push(encode(&forces).unwrap());
            let full = &all[which % all.len()];
            let n = ((full.len() as f64) * cut) as usize;
            // Any strict prefix is an incomplete message: always an error.
            let truncated = &full[..n.min(full.len() - 1)];
            prop_assert!(decode::<Command>(truncated, RUN).is_err());
            prop_assert!(decode::<Status>(truncated, RUN).is_err());
            prop_assert!(decode::<InterfaceKinematics>(truncated, RUN).is_err());
            decode_all(truncated);
            let mut mutated = full.clone();
            let i = flip.0 % mutated.len();
            mutated[i] ^= flip.1;
            decode_all(&mutated);
        }

        /// The blockwise finiteness test finds the first NaN or infinity at any place, among
        /// the values closest to the limit (largest finite, subnormals, signed zeros).
        #[test]
        fn first_non_finite_finds_the_first_bad_value(
            len in 0usize..2000,
            bad in proptest::collection::vec((0usize..2000, 0usize..3), 0..3),
            fill in proptest::collection::vec(0usize..6, 1..8),
        ) {
            let edge = [f64::MAX, -f64::MAX, f64::MIN_POSITIVE / 4.0, -0.0, 0.0, 1.0];
            let mut v: Vec<f64> = (0..len).map(|i| edge[fill[i % fill.len()]]).collect();
            let mut expected: Option<usize> = None;
            for &(i, kind) in &bad {
                if i < len {
                    v[i] = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY][kind];
                    expected = Some(expected.map_or(i, |e: usize| e.min(i)));
                }
            }
            let got = F64Array(v.clone()).first_non_finite();
            prop_assert_eq!(got.map(|(i, _)| i), expected);
            if let Some((i, x)) = got {
                prop_assert_eq!(x.to_bits(), v[i].to_bits());
            }
        }
    }

    /// The one-pass paths: encoding into a buffer with the check says "finite" only when every
    /// bulk value is; decoding with the check gives the same message and says whether it is
    /// finite, and `validate` then names the bad value as it always did.
    #[test]
    fn checked_encoding_and_decoding_find_every_non_finite_value() {
        let (_, _, _, kin, forces) = all_messages();
        let mut big = kin.clone();
        for a in [
            &mut big.positions,
            &mut big.velocities,
            &mut big.accelerations,
        ] {
            a.0 = (0..3 * 700).map(|i| i as f64 * 0.5 - 3.0).collect();
        }
        fn roundtrip<M: Message>(m: &M) -> (bool, bool) {
            let mut buf = vec![0u8; encoded_len(m).unwrap()];
            let sent_finite = encode_into_checked(m, &mut buf).unwrap();
            assert!(buf == encode(m).unwrap(), "{} encoded differently", M::WHAT);
            let (back, finite) = decode_finite::<M>(&buf, RUN).unwrap();
            // bitwise the same message (NaN != NaN, so compare the encodings)
            assert!(
                encode(&back).unwrap() == buf,
                "{} decoded differently",
                M::WHAT
            );
            (sent_finite, finite)
        }
        assert_eq!(roundtrip(&big), (true, true));
        assert!(roundtrip(&forces).1);
        // arrays of fewer than 8 doubles are not judged on the way out: "not known" (and
        // fine on the way in)
        let mut short = big.clone();
        short.velocities.0.truncate(7);
        assert_eq!(roundtrip(&short), (false, true));
        // a long name is not taken for an array: "not known", even when it balances the
        // bytes of a skipped short array... (8 doubles = 64 bytes, the shortest judged write)
        let mut named = big.clone();
        named.interface = "n".repeat(64);
        assert_eq!(roundtrip(&named), (false, true));
        // two skipped arrays (7 + 1 doubles = 64 bytes, one with a NaN) and a 64-byte name:
        // the checked bytes equal the bulk bytes, the number of checked writes does not
        let mut balanced = short.clone();
        balanced.velocities.0[3] = f64::NAN;
        balanced.accelerations.0.truncate(1);
        balanced.interface = "n".repeat(64);
        assert_eq!(roundtrip(&balanced), (false, false));
        for (field, index) in [(0usize, 0usize), (1, 1234), (2, 2099), (2, 2096)] {
            for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
                let mut m = big.clone();
                let a = match field {
                    0 => &mut m.positions,
                    1 => &mut m.velocities,
                    _ => &mut m.accelerations,
                };
                a.0[index] = bad;
                assert_eq!(roundtrip(&m), (false, false), "field {field} index {index}");
                let (back, _) =
                    decode_finite::<InterfaceKinematics>(&encode(&m).unwrap(), RUN).unwrap();
                let e = back.validate(700, back.label()).unwrap_err();
                let name = ["positions", "velocities", "accelerations"][field];
                assert!(
                    matches!(&e, ProtoError::NotFinite { field: f, index: i, .. } if *f == name && *i == index),
                    "{e}"
                );
            }
        }
    }

    /// `encode_into_checked` writes exactly the bytes of `encode` into a buffer of `encoded_len`, and
    /// refuses a buffer of another size.
    #[test]
    fn encoding_into_a_sized_buffer_matches_encode() {
        let (commands, statuses, mesh, kin, forces) = all_messages();
        fn check<M: Message>(m: &M) {
            let bytes = encode(m).unwrap();
            let n = encoded_len(m).unwrap();
            assert_eq!(n, bytes.len(), "{}", M::WHAT);
            let mut buf = vec![0u8; n];
            encode_into_checked(m, &mut buf).unwrap();
            assert_eq!(buf, bytes, "{}", M::WHAT);
            let mut long = vec![0u8; n + 1];
            assert!(encode_into_checked(m, &mut long).is_err());
            let mut short = vec![0u8; n - 1];
            assert!(encode_into_checked(m, &mut short).is_err());
        }
        commands.iter().for_each(check);
        statuses.iter().for_each(check);
        check(&mesh);
        check(&kin);
        check(&forces);
    }
}
