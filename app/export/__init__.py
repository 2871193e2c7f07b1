"""What the viewer writes to files: the Export video and Screenshot jobs (:mod:`.job`),
``texvocab shot`` (:mod:`.shot`, headless) and the GL panels of ``texvocab render
--panels`` (:mod:`.clip_panels`)."""
