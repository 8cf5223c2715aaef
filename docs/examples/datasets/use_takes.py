from mocapkit.train.config import compose_config
from mocapkit.train.training import build_datamodule

# the graph-network recipe of HDM05 on the new data set: `data=takes` picks configs/data/takes.yaml
cfg = compose_config(["experiment=hdm05_gcn", "data=takes", "data.root=data/takes", "data.test_performers=[dg]"])
data = build_datamodule(cfg)
batch = next(iter(data.train_dataloader()))

print(data.describe())
print({key: tuple(value.shape) for key, value in batch.items()})
assert data.class_names == ["jumpingJack1Reps", "walk2StepsLstart"]
skeletons = batch["skeletons"]  # [B, bodies, frames, joints, xyz], metres
assert skeletons.shape[1] == 1 and skeletons.shape[3:] == (31, 3)  # one body, the cmu31 joints
assert set(batch["subjects"].tolist()) <= {0, 1}  # performers bd and bk train; dg is held out
