set -e
B=/work/main/build-isa-avx512/hashcc; F=/work/shared/data/llff/fern
common="--data $F --images images_8 --field grid --grid-density-init 2 --lr-pose 3e-3 --threads 1 --c2f 0 --fx-only --focal-delay 0.2"
$B train $common --out /work/exp/Bc_a --cameras-from /work/exp/B30_r6/stage6 --steps 2500
# what is left of B's 30 minutes after its stages 1-6 (1,025 s) and stage a
left=$(python3 -c "import csv;r=list(csv.reader(open('/work/exp/Bc_a/camera_error.csv')));print((1800-1025-float(r[-1][1]))/60)")
echo "stage b minutes: $left"
$B train $common --out /work/exp/Bc_b --cameras-from /work/exp/Bc_a --minutes $left
