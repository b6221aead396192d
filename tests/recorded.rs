//! Uploads and writes recorded into a command buffer (`Context::upload_storage_recorded`,
//! `Context::write_recorded`, what an engine's own buffers go through): the bytes arrive once the
//! command buffer has run, any staging buffer comes back to outlive it, and more bytes than the
//! buffer holds are an error that records nothing.

mod common;

#[test]
fn recorded_uploads_and_writes_arrive() {
    let ctx = common::context();
    let mut made = None;
    ctx.submit("recorded upload", |_, cmd| {
        made = Some(ctx.upload_storage_recorded("data", &[1u32, 2, 3, 4], cmd));
    })
    .unwrap();
    let (mut data, staging) = made.unwrap().unwrap();
    drop(staging);
    assert_eq!(ctx.read::<u32>(&mut data).unwrap(), [1, 2, 3, 4]);
    let mut written = None;
    ctx.submit("recorded write", |_, cmd| {
        written = Some(ctx.write_recorded(&mut data, bytemuck::cast_slice(&[7u32, 8]), cmd));
    })
    .unwrap();
    drop(written.unwrap().unwrap());
    assert_eq!(ctx.read::<u32>(&mut data).unwrap(), [7, 8, 3, 4]);
    let mut too_many = None;
    ctx.submit("recorded write past the end", |_, cmd| {
        too_many = Some(ctx.write_recorded(&mut data, &[0u8; 20], cmd));
    })
    .unwrap();
    assert!(too_many.unwrap().is_err());
    assert_eq!(ctx.read::<u32>(&mut data).unwrap(), [7, 8, 3, 4]);
}
