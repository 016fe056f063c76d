//! Unit tests of `embedded`.

use super::*;

fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("penumbra-store-{}-{name}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    dir
}

#[test]
fn jobs_survive_reopening_and_move_through_their_states() {
    let dir = temp_dir("states");
    {
        let store = EmbeddedStore::open(&dir).unwrap();
        store.accept("a", &serde_json::json!({"scene": {"builtin": "torus"}})).unwrap();
        store.accept("b", &serde_json::json!({"scene": {"builtin": "crowd"}})).unwrap();
        store.start("a").unwrap();
        store.accept("c", &serde_json::json!({})).unwrap();
        store.start("c").unwrap();
        store.succeed("c", &serde_json::json!({"width": 4}), b"png bytes").unwrap();
    }
    // As after a crash: a new process opens the same directory.
    let store = EmbeddedStore::open(&dir).unwrap();
    let unfinished: Vec<(String, JobStatus, u32)> = store.unfinished().unwrap().into_iter().map(|j| (j.id, j.status, j.attempts)).collect();
    assert_eq!(unfinished, vec![("a".into(), JobStatus::Running, 1), ("b".into(), JobStatus::Queued, 0)]);
    let c = store.get("c").unwrap().unwrap();
    assert_eq!((c.status, c.image_bytes, c.result.unwrap()["width"].as_u64()), (JobStatus::Succeeded, 9, Some(4)));
    assert_eq!(store.image("c").unwrap().unwrap(), b"png bytes");
    store.fail("b", &serde_json::json!({"code": "internal"})).unwrap();
    assert_eq!(store.get("b").unwrap().unwrap().status, JobStatus::Failed);
    assert!(store.get("zzz").unwrap().is_none() && store.start("zzz").is_err());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_existing_id_is_refused_not_overwritten() {
    let dir = temp_dir("exists");
    let store = EmbeddedStore::open(&dir).unwrap();
    store.accept("same", &serde_json::json!({"method": {"name": "hard"}})).unwrap();
    let again = store.accept("same", &serde_json::json!({"method": {"name": "wedges"}}));
    assert!(matches!(again, Err(StoreError::Exists(ref id)) if id == "same"), "{again:?}");
    assert_eq!(store.get("same").unwrap().unwrap().job["method"]["name"], "hard");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn finished_jobs_expire_by_age_and_images_by_bytes() {
    let dir = temp_dir("expiry");
    let store = EmbeddedStore::open(&dir).unwrap();
    for (id, size) in [("old", 10), ("mid", 20), ("new", 30)] {
        store.accept(id, &Value::Null).unwrap();
        store.succeed(id, &Value::Null, &vec![0u8; size]).unwrap();
        std::thread::sleep(Duration::from_millis(5));
    }
    store.accept("waiting", &Value::Null).unwrap();
    // 50 bytes of images allowed: the oldest image goes, its record stays.
    assert_eq!(store.expire(Duration::from_secs(3600), 50).unwrap(), (0, 1));
    assert!(store.image("old").unwrap().is_none() && store.get("old").unwrap().is_some());
    assert!(store.image("mid").unwrap().is_some());
    // Everything finished is older than zero seconds: records go; unfinished jobs stay.
    std::thread::sleep(Duration::from_millis(5));
    assert_eq!(store.expire(Duration::ZERO, u64::MAX).unwrap().0, 3);
    assert!(store.get("new").unwrap().is_none() && store.image("new").unwrap().is_none());
    assert_eq!(store.unfinished().unwrap().len(), 1);
    assert_eq!(std::fs::read_dir(dir.join("images")).unwrap().count(), 0, "every image file went with its record");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_image_without_a_recorded_success_is_removed_at_open() {
    let dir = temp_dir("orphans");
    {
        let store = EmbeddedStore::open(&dir).unwrap();
        store.accept("kept", &Value::Null).unwrap();
        store.succeed("kept", &Value::Null, b"kept").unwrap();
    }
    // As after a crash between the image file and its record.
    std::fs::write(dir.join("images/lost"), b"lost").unwrap();
    std::fs::write(dir.join("images/half.part"), b"half").unwrap();
    let store = EmbeddedStore::open(&dir).unwrap();
    let mut files: Vec<String> =
        std::fs::read_dir(dir.join("images")).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    files.sort();
    assert_eq!(files, ["kept"]);
    assert_eq!(store.image("kept").unwrap().unwrap(), b"kept");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn make_room_drops_the_oldest_images_first() {
    let dir = temp_dir("room");
    let store = EmbeddedStore::open(&dir).unwrap();
    for id in ["first", "second"] {
        store.accept(id, &Value::Null).unwrap();
        store.succeed(id, &Value::Null, b"image").unwrap();
        std::thread::sleep(Duration::from_millis(5));
    }
    // Asking for more than any disk has drops every image, oldest first, and keeps records.
    assert_eq!(store.make_room(u64::MAX).unwrap(), 2);
    assert!(store.image("first").unwrap().is_none() && store.get("first").unwrap().unwrap().image_bytes == 0);
    // Asking for nothing drops nothing.
    assert_eq!(store.make_room(0).unwrap(), 0);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn an_idempotency_key_names_its_job_while_both_last() {
    use crate::job::submission::KeyedJob;
    let dir = temp_dir("keys");
    let store = EmbeddedStore::open(&dir).unwrap().with_max_keys(2);
    let claim =
        |id: &str, fingerprint: &str| KeyedJob { id: id.into(), fingerprint: fingerprint.into(), expires_unix_ms: unix_ms() + 60_000 };
    let job = serde_json::json!({"scene": {"builtin": "torus"}});
    assert_eq!(store.accept_keyed(&StoredJob::queued("first", &job), "key", &claim("first", "f1")).unwrap(), None);
    assert_eq!(store.keyed("key").unwrap().map(|k| k.id), Some("first".into()));
    // A twin: the first job is answered, nothing written.
    let twin = store.accept_keyed(&StoredJob::queued("twin", &job), "key", &claim("twin", "f1")).unwrap();
    assert_eq!(twin.map(|k| k.id), Some("first".into()));
    assert!(store.get("twin").unwrap().is_none());
    // Once its record expired, the key is claimed anew.
    store.fail("first", &serde_json::json!({"code": "internal"})).unwrap();
    std::thread::sleep(Duration::from_millis(5));
    assert_eq!(store.expire(Duration::ZERO, u64::MAX).unwrap().0, 1);
    assert!(store.keyed("key").unwrap().is_none());
    assert_eq!(store.accept_keyed(&StoredJob::queued("second", &job), "key", &claim("second", "f2")).unwrap(), None);
    // Past the cap, the oldest key goes.
    for (n, key) in ["k1", "k2", "k3"].iter().enumerate() {
        let id = format!("job-{n}");
        store.accept_keyed(&StoredJob::queued(&id, &job), key, &claim(&id, "f")).unwrap();
    }
    assert!(store.keyed("k3").unwrap().is_some());
    std::fs::remove_dir_all(&dir).ok();
}
