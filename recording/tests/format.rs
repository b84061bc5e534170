//! The recording format: round trip, files from other programs, malformed files.

use pcr_recording::{Recording, RecordingError, RecordingWriter, Row};

fn read(text: &str) -> Result<Recording, RecordingError> {
    Recording::read(text.as_bytes(), "test.csv")
}

#[test]
fn round_trip_keeps_metadata_values_and_empty_cells() {
    let mut buf = Vec::new();
    let meta = vec![
        ("robot".to_string(), "configs/robot.toml".to_string()),
        ("source".to_string(), "pcr plant run".to_string()),
    ];
    let mut w = RecordingWriter::new(
        &mut buf,
        &meta,
        &["x_mm", "y_mm", "phi_deg", "m1x_mm", "settled"],
        &["x_true_mm"],
    )
    .unwrap();
    let mut r = Row::new(0.0, [176, 176, 176]);
    r.pose = [Some(0.1), Some(-0.2), None];
    r.m[0] = [Some(-209.25), None];
    r.settled = Some(true);
    w.write_row(&r, &[Some(0.125)]).unwrap();
    let r2 = Row::new(0.02, [177, -3, 176]);
    w.write_row(&r2, &[None]).unwrap();
    drop(w);
    let text = String::from_utf8(buf).unwrap();
    let rec = read(&text).unwrap();
    assert_eq!(rec.meta("robot"), Some("configs/robot.toml"));
    assert_eq!(rec.meta("source"), Some("pcr plant run"));
    assert_eq!(rec.extra_columns, vec!["x_true_mm"]);
    assert_eq!(rec.rows.len(), 2);
    let mut want = r.clone();
    want.extra = vec![Some("0.125".into())];
    assert_eq!(rec.rows[0], want);
    assert_eq!(rec.rows[1].q, [177, -3, 176]);
    assert_eq!(rec.rows[1].pose, [None; 3]);
    assert_eq!(rec.rows[1].extra, vec![None]);
}

#[test]
fn reads_files_of_other_programs() {
    let text = "# robot = lab-2\n# a free comment\n# created = 2026-11-01T10:00:00Z\n\
                foo,q3,t_s,q1,q2,x_mm,bar\n\
                \"a,b\",176,0.000,176,176,1.5,\n\
                c,177,0.020,176.0,176,,7\n";
    let rec = read(text).unwrap();
    assert_eq!(rec.meta("robot"), Some("lab-2"));
    assert_eq!(rec.meta("created"), Some("2026-11-01T10:00:00Z"));
    assert_eq!(rec.comments, vec!["a free comment"]);
    assert_eq!(rec.extra_columns, vec!["foo", "bar"]);
    assert_eq!(rec.rows[0].extra, vec![Some("a,b".into()), None]);
    assert_eq!(rec.rows[1].q, [176, 176, 177]);
    assert_eq!(rec.rows[0].pose[0], Some(1.5));
    assert_eq!(rec.rows[1].pose[0], None);
}

fn err(text: &str) -> String {
    read(text).unwrap_err().to_string()
}

#[test]
fn malformed_files_fail_naming_line_and_column() {
    let h = "# robot = x\nt_s,q1,q2,q3,x_mm\n";
    let e = err(&format!("{h}0,1,2,3,1.0\n0.02,1,2,3,abc\n"));
    assert!(
        e.contains("line 4") && e.contains("`x_mm`") && e.contains("abc"),
        "{e}"
    );
    let e = err(&format!("{h}0,1,2,3,NaN\n"));
    assert!(e.contains("line 3") && e.contains("NaN"), "{e}");
    let e = err(&format!("{h}0,1,2,3,1,0\n"));
    assert!(e.contains("line 3") && e.contains("6 cells"), "{e}");
    let e = err(&format!("{h}0.02,1,2,3,\n0.02,1,2,3,\n"));
    assert!(
        e.contains("line 4") && e.contains("t_s") && e.contains("increase"),
        "{e}"
    );
    let e = err(&format!("{h}0.02,1,2,3,\n0.01,1,2,3,\n"));
    assert!(e.contains("line 4") && e.contains("increase"), "{e}");
    let e = err(&format!("{h}0,1.5,2,3,\n"));
    assert!(e.contains("`q1`") && e.contains("integer"), "{e}");
    let e = err(&format!("{h}0,,2,3,\n"));
    assert!(e.contains("`q1`") && e.contains("required"), "{e}");
    let e = err(&format!("{h}0,1,2,3,1e999\n"));
    assert!(e.contains("finite"), "{e}");
    let e = err(&format!("{h}0,1,2,3,\"1,5\"\n"));
    assert!(e.contains("`x_mm`"), "{e}");
    let e = err("t_s,q1,q2,x_mm\n0,1,2,3\n");
    assert!(e.contains("`q3`") && e.contains("missing"), "{e}");
    let e = err("t_s,q1,q2,q3,q1\n");
    assert!(e.contains("twice"), "{e}");
    let e = err("# only comments\n");
    assert!(e.contains("no header"), "{e}");
    let e = err("t_s,q1,q2,q3,settled\n0,1,2,3,2\n");
    assert!(e.contains("`settled`") && e.contains("0 or 1"), "{e}");
}

#[test]
fn writer_refuses_nan_and_time_going_back() {
    let mut buf = Vec::new();
    let mut w = RecordingWriter::new(&mut buf, &[], &["x_mm"], &[]).unwrap();
    let mut r = Row::new(0.0, [0, 0, 0]);
    r.pose[0] = Some(f64::NAN);
    assert!(w.write_row(&r, &[]).is_err());
    w.write_row(&Row::new(0.0, [0, 0, 0]), &[]).unwrap();
    assert!(w.write_row(&Row::new(0.0, [0, 0, 0]), &[]).is_err());
}

#[test]
fn writer_flushes_every_row() {
    let dir = std::env::temp_dir().join(format!("pcr-recording-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rec.csv");
    let mut w = RecordingWriter::create(&path, &[], &["x_mm"], &[]).unwrap();
    w.write_row(&Row::new(0.0, [1, 2, 3]), &[]).unwrap();
    w.write_row(&Row::new(0.02, [1, 2, 4]), &[]).unwrap();
    // Without dropping the writer, the file already holds both rows.
    let rec = Recording::read_path(&path).unwrap();
    assert_eq!(rec.rows.len(), 2);
    drop(w);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn whole_recording_round_trip_keeps_unknown_columns() {
    let text = "# robot = lab-2\n# a free comment\n\
                foo,q3,t_s,q1,q2,x_mm,settled,bar\n\
                \"a,b\",176,0.000,176,176,1.5,1,\n\
                c,177,0.020,176.0,176,,,7\n";
    let rec = read(text).unwrap();
    let mut buf = Vec::new();
    rec.write(&mut buf).unwrap();
    let back = read(std::str::from_utf8(&buf).unwrap()).unwrap();
    assert_eq!(back.metadata, rec.metadata);
    assert_eq!(back.comments, rec.comments);
    assert_eq!(back.extra_columns, rec.extra_columns);
    assert_eq!(back.rows, rec.rows);
}

#[test]
fn numbers_are_written_compactly_and_read_back_exactly() {
    for x in [
        0.0,
        -0.0,
        1.5,
        -209.46613071,
        1e-27,
        -3.3e-31,
        2e16,
        0.02,
        1e-6,
        123456.789,
    ] {
        let t = pcr_recording::number(x);
        assert!(t.len() < 26, "{t}");
        assert_eq!(t.parse::<f64>().unwrap(), x, "{t}");
    }
}

#[test]
fn set_column_reads_and_writes_train_and_test() {
    let r = read("t_s,q1,q2,q3,set\n0,1,2,3,train\n1,1,2,3,test\n2,1,2,3,\n").unwrap();
    assert_eq!(r.rows[0].set, Some(pcr_recording::Split::Train));
    assert_eq!(r.rows[1].set, Some(pcr_recording::Split::Test));
    assert_eq!(r.rows[2].set, None);
    let mut out = Vec::new();
    r.write(&mut out).unwrap();
    let text = String::from_utf8(out).unwrap();
    assert!(
        text.contains("t_s,q1,q2,q3,set\n0,1,2,3,train\n1,1,2,3,test\n2,1,2,3,\n"),
        "{text}"
    );
    let e = err("t_s,q1,q2,q3,set\n0,1,2,3,validation\n");
    assert!(e.contains("`set`") && e.contains("train"), "{e}");
}

#[test]
fn text_extra_cells_are_written_and_read_back() {
    let mut buf = Vec::new();
    let mut w = RecordingWriter::new(&mut buf, &[], &["settled"], &["segment", "motor"]).unwrap();
    let mut r = Row::new(0.0, [1, 2, 3]);
    r.settled = Some(false);
    w.write_row_text(&r, &[Some("circle"), None]).unwrap();
    w.write_row_text(&Row::new(0.02, [1, 2, 3]), &[None, Some("2")])
        .unwrap();
    assert!(w
        .write_row_text(&Row::new(0.04, [1, 2, 3]), &[Some("a\nb"), None])
        .is_err());
    assert!(w
        .write_row_text(&Row::new(0.06, [1, 2, 3]), &[None])
        .is_err());
    assert!(w
        .write_row_text(&Row::new(0.02, [1, 2, 3]), &[None, None])
        .is_err());
    drop(w);
    let rec = Recording::read(&buf[..], "t.csv").unwrap();
    assert_eq!(rec.extra_columns, ["segment", "motor"]);
    assert_eq!(rec.rows[0].extra, [Some("circle".to_string()), None]);
    assert_eq!(rec.rows[1].extra, [None, Some("2".to_string())]);
    assert_eq!(rec.rows.len(), 2);
}

#[test]
fn the_timing_contract_defaults_to_zero_and_reads_the_declared_delay() {
    let plain = read("t_s,q1,q2,q3\n0,1,2,3\n").unwrap();
    assert_eq!(plain.command_delay_s().unwrap(), 0.0);
    assert!(!plain.declares_command_delay());
    let chain = read("# command_delay_s = 0.02\nt_s,q1,q2,q3\n0,1,2,3\n").unwrap();
    assert_eq!(chain.command_delay_s().unwrap(), 0.02);
    assert!(chain.declares_command_delay());
}

#[test]
fn a_bad_command_delay_is_an_error_naming_the_line_and_key() {
    for bad in ["abc", "-0.02", "inf", "NaN"] {
        let text =
            format!("# source = other lab\n# command_delay_s = {bad}\nt_s,q1,q2,q3\n0,1,2,3\n");
        let e = read(&text).unwrap_err();
        let msg = e.to_string();
        assert!(
            matches!(e, RecordingError::Metadata { line: 2, .. }),
            "{bad}: {msg}"
        );
        assert!(
            msg.contains("test.csv: line 2") && msg.contains("command_delay_s"),
            "{msg}"
        );
    }
}
