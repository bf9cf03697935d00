\ Seed 004's PP-TEST on slave 1 of the EtherCAT master:
\ omni-master --script tests/data/ethercat/pp_test.fs --iface SPEC --config tests/data/ethercat/drives_only.yaml
: pp-test
    pp 1 1 op-mode!
    until-no-requests
    1 1 reset-fault
    1 1 until-no-fault
    1 1 drive-on
    1 1 until-drive-on
    1000 1 1 target-p!
    1 1 go
    1 1 until-target-reached
    ." target reached: " 1 1 real-p@ . cr
;
deploy pp-test ;deploy
